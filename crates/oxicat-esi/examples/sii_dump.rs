//! Prints the model of an SII image (binary or Intel HEX): `cargo run --example sii_dump FILE`.
fn main() {
    let Some(p) = std::env::args().nth(1) else {
        eprintln!("usage: sii_dump FILE");
        std::process::exit(2);
    };
    match std::fs::read(&p).map(|b| oxicat_esi::sii::parse_any(&b)) {
        Ok(Ok(m)) => println!("{m:#?}"),
        Ok(Err(e)) => eprintln!("{p}: {e}"),
        Err(e) => eprintln!("{p}: {e}"),
    }
}

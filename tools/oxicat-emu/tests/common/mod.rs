//! What the emulator's tests share: finding a board image.

use std::path::PathBuf;

/// The release ELF of `firmware/<board>` that `.ci/run` builds before the tests: the file
/// named by the environment variable `env` if set, else in `CARGO_TARGET_DIR` when the build
/// used one, or in the firmware's own target directory. Missing: a failure under `CI`
/// (the image must be there), else `None` with the reason on standard error.
pub fn image(board: &str, env: &str) -> Option<Vec<u8>> {
    let elf = format!("thumbv7em-none-eabihf/release/oxicat-firmware-{board}");
    let own = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../firmware")
        .join(board)
        .join("target")
        .join(&elf);
    let candidates: Vec<PathBuf> = match std::env::var_os(env) {
        Some(p) => vec![PathBuf::from(p)],
        None => std::env::var_os("CARGO_TARGET_DIR")
            .map(|d| PathBuf::from(d).join(&elf))
            .into_iter()
            .chain([own])
            .collect(),
    };
    for p in &candidates {
        if let Ok(b) = std::fs::read(p) {
            return Some(b);
        }
    }
    let tried: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
    let msg = format!(
        "no {board} image at {} (build it: cd firmware/{board} && cargo build --release --locked)",
        tried.join(" or ")
    );
    if std::env::var_os("CI").is_some() {
        panic!("{msg}");
    }
    eprintln!("skipped: {msg}");
    None
}

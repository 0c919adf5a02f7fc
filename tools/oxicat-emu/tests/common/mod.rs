//! What the emulator's tests share: finding a board image, a master that talks to one
//! board's ESC directly.

use std::path::PathBuf;

use oxicat_emu::{Board, EscChip};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader, EcatFrame};

/// The release ELF of `firmware/<board>` that `.ci/run` builds before the tests: the file
/// named by the environment variable `env` if set, else in `CARGO_TARGET_DIR` when the build
/// used one, or in the firmware images' shared target directory (`firmware/target`). Missing: a failure under `CI`
/// (the image must be there), else `None` with the reason on standard error.
#[allow(dead_code)] // not every test binary uses it
pub fn image(board: &str, env: &str) -> Option<Vec<u8>> {
    image_in(board, "", env)
}

/// [`image`] for a build with a target directory of its own, `sub` below the usual one
/// (the left leg's build: `--target-dir ../target/left`).
pub fn image_in(board: &str, sub: &str, env: &str) -> Option<Vec<u8>> {
    let elf = PathBuf::from(sub).join(format!(
        "thumbv7em-none-eabihf/release/oxicat-firmware-{board}"
    ));
    let own = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../firmware/target")
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
        "no {board} image at {} (build it: cd firmware/{board} && cargo build --release --locked{})",
        tried.join(" or "),
        if sub.is_empty() { String::new() } else { format!(" … --target-dir ../target/{sub}") }
    );
    if std::env::var_os("CI").is_some() {
        panic!("{msg}");
    }
    eprintln!("skipped: {msg}");
    None
}

/// The master's side: single datagrams to the one ESC (position 0) at the board's time.
#[allow(dead_code)] // not every test binary uses it
pub struct Direct {
    /// The chip whose ESC the frames walk through.
    pub chip: EscChip,
}

#[allow(dead_code)]
impl Direct {
    pub fn frame(&self, board: &Board, cmd: Command, ado: u16, data: &[u8]) -> (Vec<u8>, u16) {
        let mut buf = vec![0u8; 1600];
        let mut fb = FrameBuilder::new_bare(&mut buf).unwrap();
        fb.push(
            DatagramHeader::physical(cmd, 0, 0, ado, data.len() as u16),
            data,
        )
        .unwrap();
        let n = fb.finish();
        buf.truncate(n);
        let t = board.time_ns();
        self.chip.with_esc(|esc| esc.forward(0, &mut buf, t, true));
        let f = EcatFrame::parse(&buf).unwrap();
        let d = f.datagrams().next().unwrap().unwrap();
        (d.data.to_vec(), d.wkc)
    }

    pub fn wr(&self, b: &Board, ado: u16, data: &[u8]) {
        assert_eq!(
            self.frame(b, Command::Apwr, ado, data).1,
            1,
            "APWR {ado:#06x}"
        );
    }

    pub fn rd(&self, b: &Board, ado: u16, len: usize) -> Vec<u8> {
        let (d, wkc) = self.frame(b, Command::Aprd, ado, &vec![0; len]);
        assert_eq!(wkc, 1, "APRD {ado:#06x}");
        d
    }

    pub fn al_status(&self, b: &Board) -> u16 {
        let s = self.rd(b, 0x0130, 2);
        u16::from_le_bytes([s[0], s[1]])
    }

    /// A master's first steps: the two mailbox SyncManagers (SM0 at 0x1000, SM1 at 0x1080,
    /// 128 bytes each), then INIT → PREOP, waiting at most `timeout_ns` of board time.
    pub fn to_preop(&self, b: &mut Board, timeout_ns: u64) {
        let sm = |start: u16, ctrl: u8| {
            let mut r = [0u8; 8];
            r[..2].copy_from_slice(&start.to_le_bytes());
            r[2..4].copy_from_slice(&128u16.to_le_bytes());
            r[4] = ctrl;
            r[6] = 1;
            r
        };
        self.wr(b, 0x0800, &sm(0x1000, 0x26));
        self.wr(b, 0x0808, &sm(0x1080, 0x22));
        self.wr(b, 0x0120, &2u16.to_le_bytes());
        let preop = b
            .run_until(50_000, timeout_ns, |b| self.al_status(b) & 0x1F == 0x02)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(preop, "AL status {:#06x}", self.al_status(b));
    }

    /// 0x1018:01..03 over SDO are `id`'s vendor, product code and revision.
    pub fn assert_identity(&self, b: &mut Board, id: oxicat_slave::Identity) {
        assert_eq!(self.sdo_u32(b, 1, 0x1018, 1), id.vendor_id);
        assert_eq!(self.sdo_u32(b, 2, 0x1018, 2), id.product_code);
        assert_eq!(self.sdo_u32(b, 3, 0x1018, 3), id.revision);
    }

    /// SDO upload of `index:sub` (expedited, 4 bytes) through the mailbox.
    pub fn sdo_u32(&self, b: &mut Board, counter: u8, index: u16, sub: u8) -> u32 {
        let mut req = vec![0u8; 128];
        req[..6].copy_from_slice(&[10, 0, 0, 0, 0, 0x03 | (counter << 4)]);
        req[6..8].copy_from_slice(&0x2000u16.to_le_bytes());
        let [lo, hi] = index.to_le_bytes();
        req[8..16].copy_from_slice(&[0x40, lo, hi, sub, 0, 0, 0, 0]);
        self.wr(b, 0x1000, &req);
        let full = |b: &mut Board| self.rd(b, 0x080D, 1)[0] & 0x08 != 0;
        let answered = b
            .run_until(50_000, 20_000_000, full)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(answered, "no SDO response to {index:#06x}:{sub}");
        let resp = self.rd(b, 0x1080, 128);
        assert_eq!(resp[5] & 0x0F, 0x03, "a CoE reply");
        assert_eq!(
            u16::from_le_bytes([resp[6], resp[7]]) >> 12,
            3,
            "SDO response"
        );
        assert_eq!(
            resp[8],
            0x43,
            "expedited upload of 4 bytes: {:02x?}",
            &resp[..16]
        );
        u32::from_le_bytes([resp[12], resp[13], resp[14], resp[15]])
    }
}

#[allow(unused_imports)] // not every test binary uses it
pub use oxicat_testkit::big;

//! Segment files a user hands `oxicat sim --segment` (`oxicat::sim_cmd::parse_segment`),
//! and, for small segments, building them (`build_segment`: devices booted, delays set).
//! Nothing may panic: a bad file is an error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(seg) = oxicat::sim_cmd::parse_segment(text, Path::new("fuzz.toml")) else {
        return;
    };
    // Booting firmware is slow: only small segments (large ones are item 10's limits).
    let nodes: usize = seg.devices.iter().map(|d| d.count.min(100)).sum();
    if nodes <= 4 {
        let _ = oxicat::sim_cmd::build_segment(&seg);
    }
});

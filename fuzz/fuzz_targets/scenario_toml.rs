//! Scenario files a user hands `trot --scenario` (`oxicat_devices::laelaps::scenario::Scenario::parse`,
//! TOML and the range checks). Nothing may panic: a bad file is an error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_devices::laelaps::scenario::Scenario;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = Scenario::parse(text);
    }
});

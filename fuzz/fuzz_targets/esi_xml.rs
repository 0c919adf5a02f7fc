//! ESI XML files a user hands the CLI (`device check`, the replay bench), through
//! `oxicat_esi::esi::parse`. Nothing may panic; every model it returns compares equal
//! to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(models) = oxicat_esi::esi::parse(text) {
        for m in &models {
            assert!(
                oxicat_esi::compare(m, m).is_empty(),
                "a model differs from itself"
            );
        }
    }
});

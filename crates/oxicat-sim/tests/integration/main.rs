//! The crate's integration tests, one module per file, in one test binary: the crate's
//! code and its generic stack are compiled and linked once for all of them instead of
//! once per file (`cargo test -p oxicat-sim --test integration <module>::`).

mod capture_tshark;
mod configured_dispatch;
mod dc_converges;
mod demo_sii_ethercrab;
mod faults;
mod real_devices;
mod replay;
#[path = "../replay_bench/mod.rs"]
mod replay_bench;
mod rt;
mod scheduler_equivalence;
#[path = "../segment_common/mod.rs"]
mod segment_common;
#[path = "../stack_common/mod.rs"]
mod stack_common;
mod stack_dynamic_pdo;
mod stack_modes;
mod stack_watchdog;

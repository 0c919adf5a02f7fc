//! What several of this crate's integration tests share.

use oxicat_devices::{axis_hub, cia402, demo, laelaps, tue_es030};
use oxicat_slave::DeviceDef;

/// Every device a board image of this repository runs, by name.
pub fn board_devices() -> [(&'static str, &'static DeviceDef); 7] {
    [
        ("demo", &demo::DEF),
        ("demo additions", &demo::additions::DEF),
        (
            "laelaps left",
            laelaps::device::device(laelaps::kinematics::Side::Left),
        ),
        (
            "laelaps right",
            laelaps::device::device(laelaps::kinematics::Side::Right),
        ),
        ("cia402", &cia402::device::DEF),
        ("tue-es030", &tue_es030::device::DEF),
        ("axis hub", &axis_hub::device::DEF),
    ]
}

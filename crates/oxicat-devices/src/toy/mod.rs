//! A toy device, added by the README's "Add a device" recipe to prove it (feature `toy`,
//! test builds only): one INT16 output, one INT16 input that echoes it plus one, and a cycle
//! counter. Its whole diff is this folder, its line in the registry and its `mod` line.

use oxicat_slave::{AlState, AlStatusCode, Application, Od};

crate::pd_table! {
    tx { 0x1A00 "Inputs" { 0x6000 "Inputs" { 1 "Echo": Int16 => echo, 2 "Cycles": Unsigned32 => cycles } } }
    rx { 0x1600 "Outputs" { 0x7000 "Outputs" { 1 "Value": Int16 => value } } }
}

/// The definition: the one source of OD, ESI and SII.
pub static DEF: oxicat_slave::DeviceDef = oxicat_slave::DeviceDef {
    identity: oxicat_slave::Identity {
        vendor_id: crate::demo::VENDOR_ID,
        product_code: 0x0000_7070,
        revision: 1,
        serial: 0,
    },
    device_type: 0x0000_1389,
    name: "oxicat toy device",
    hw_version: "virtual",
    sw_version: env!("CARGO_PKG_VERSION"),
    mailbox: oxicat_slave::MailboxDef::STANDARD,
    boot_mailbox: None,
    sm2_start: 0x1100,
    sm3_start: 0x1400,
    objects: OBJECTS,
    rx_pdos: RX_PDOS,
    tx_pdos: TX_PDOS,
    rx_assign: RX_ASSIGN,
    tx_assign: TX_ASSIGN,
    assign_configurable: false,
    sync: oxicat_slave::SyncDef {
        supported: 0x0001,
        default_mode: oxicat_slave::SyncMode::FreeRun,
        min_cycle_ns: 100_000,
        calc_copy_ns: 10_000,
    },
    info: Some(&oxicat_slave::device::DeviceInfo {
        vendor_name: "oxicat",
        group: oxicat_slave::device::Group {
            type_name: "OxicatToy",
            name: "oxicat toy devices",
        },
        order_code: "OXICAT-TOY",
        description: Some("oxicat toy device (the Add-a-device recipe)"),
        ..oxicat_slave::device::DeviceInfo::DEFAULT
    }),
};

/// The application: `Echo = Value + 1` (wrapping), `Cycles` counts cycles.
#[derive(Debug, Default)]
pub struct Toy {
    cycles: u32,
    io: Option<PdVars>,
}

impl<const N: usize> Application<N> for Toy {
    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        if to == AlState::SafeOp {
            self.io = od.built_on(OBJECTS).then_some(VARS);
        }
        Ok(())
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        let _ = od.set(0x7000, 1, 0i16);
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        self.cycles = self.cycles.wrapping_add(1);
        if let Some(io) = self.io {
            let v = od.load(io.value);
            od.store(io.echo, v.wrapping_add(1));
            od.store(io.cycles, self.cycles);
        }
    }
}

/// The toy on the virtual segment (feature `bench`).
#[cfg(feature = "bench")]
pub mod rig;

//! Verbs and output formats after the IgH `ethercat` tool that stand on their own:
//! `slaves -v` blocks, `version`, `fw-image` (a firmware image for `foe-write`) and
//! `device list`.

use std::path::Path;

use oxicat_master::SlaveInfo;

/// One slave as `ethercat slaves -v` shows it: a block of `Key: value` lines.
pub fn slave_verbose(s: &SlaveInfo) -> String {
    let mut t = format!("=== Slave {} ===\n", s.position);
    t.push_str(&format!("Device: {}\n", s.name));
    t.push_str(&format!("State: {}\n", s.status));
    t.push_str(&format!(
        "Station address: 0x{:04x}\nAlias: 0x{:04x}\n",
        s.address, s.alias
    ));
    t.push_str("Identity:\n");
    t.push_str(&format!("  Vendor Id:       0x{:08x}\n", s.vendor_id));
    t.push_str(&format!("  Product code:    0x{:08x}\n", s.product_code));
    t.push_str(&format!("  Revision number: 0x{:08x}\n", s.revision));
    t.push_str(&format!("  Serial number:   0x{:08x}\n", s.serial));
    t.push_str("Ports:\n  Port  Link  Loop\n");
    for p in 0..4 {
        t.push_str(&format!(
            "   {p}    {:<4}  {}\n",
            if s.links[p] { "up" } else { "down" },
            if s.open[p] { "open" } else { "closed" }
        ));
    }
    t.push_str(&format!("DC propagation delay: {} ns\n", s.delay_ns));
    t
}

/// `oxicat version`: the tool's name and version.
pub fn version() -> String {
    format!(
        "oxicat {} (EtherCAT master verbs on ethercrab 0.7, slave stack, virtual segment)\n",
        env!("CARGO_PKG_VERSION")
    )
}

/// `oxicat device list`: every device definition, one line each.
pub fn device_list() -> String {
    crate::devices()
        .iter()
        .map(|(n, _, d)| format!("{n:<16} {d}\n"))
        .collect()
}

/// `oxicat fw-image <device> <payload> -o <image>`: the payload wrapped in the firmware image
/// header of `device` (identity, length, CRC-32), as `foe-write` sends it.
pub fn fw_image(device: &str, payload: &Path, output: &Path) -> Result<String, crate::CliError> {
    let def = crate::devices()
        .into_iter()
        .find(|d| d.0 == device)
        .map(|d| d.1)
        .ok_or_else(|| crate::CliError::UnknownDevice(device.to_string()))?;
    let data = std::fs::read(payload).map_err(|e| {
        crate::CliError::Io(std::io::Error::new(
            e.kind(),
            format!("{}: {e}", payload.display()),
        ))
    })?;
    let img = oxicat_device::fwimage::build(def, &data);
    std::fs::write(output, &img).map_err(|e| {
        crate::CliError::Io(std::io::Error::new(
            e.kind(),
            format!("{}: {e}", output.display()),
        ))
    })?;
    Ok(format!(
        "{}: {} bytes ({} bytes of payload for {device})\n",
        output.display(),
        img.len(),
        data.len()
    ))
}

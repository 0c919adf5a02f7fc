//! The mistakes a user can make on the command line (or in a file named there), one variant
//! per kind, each with the offending value and what would be accepted. A verb refuses them
//! before it opens a link or touches a file where it can; its message names the option, the
//! value and the remedy (`--joints 0: 1 … 64 drives (…)`), never `Debug` output.
//!
//! Errors of the master library itself (a slave that does not answer, a refused SDO) stay
//! [`oxicat_master::MasterError`]; both reach the user through [`crate::CliError`].

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use oxicat_master::value::ValueType;

use crate::sim_cmd::SimError;

/// A mistake in the arguments of a verb.
#[derive(Debug)]
pub enum UsageError {
    /// Not a duration (`400us`, `1ms`, `10s`): the text given.
    NotADuration(String),
    /// A duration with a unit that is none of ns, us, µs, ms, s, m, min.
    UnknownTimeUnit {
        /// The unit.
        unit: String,
        /// The whole duration given.
        value: String,
    },
    /// `record --duration` shorter than one cycle.
    DurationBelowCycle {
        /// `--duration`.
        duration: Duration,
        /// `--cycle`.
        cycle: Duration,
    },
    /// A number outside its range: `{option} {value}: {allowed}`.
    OutOfRange {
        /// The option (`--joints`).
        option: &'static str,
        /// The value given.
        value: String,
        /// What is allowed, and why (`1 … 64 drives (…)`).
        allowed: String,
    },
    /// A number outside its bounds: `{option} {value} is not in {lo} … {hi} ({why})`.
    OutOfBounds {
        /// The option (`--i`).
        option: &'static str,
        /// The value given.
        value: String,
        /// The lowest value allowed.
        lo: String,
        /// The highest value allowed.
        hi: String,
        /// What the number is, or why the bounds.
        why: &'static str,
    },
    /// `--p` with no gain.
    NoGain,
    /// The `--sim` segment could not be parsed or built.
    Sim(SimError),
    /// A `--sim` spec with no device in it.
    SimNoDevices(String),
    /// None of `--iface`, `--udp`, `--sim` (nor `OXICAT_IFACE`).
    NoLink,
    /// `OXICAT_TIMEOUT_MS` is not a number: its value.
    TimeoutEnv(String),
    /// `--timeout 0`.
    ZeroTimeout,
    /// Not an object index or register address (u16): the text given.
    NotAnIndex(String),
    /// Not a subindex (u8): the text given.
    NotASubindex(String),
    /// Not a station alias (u16): the text given.
    NotAnAlias(String),
    /// Not an FoE password (u32): the text given.
    NotAPassword(String),
    /// Not an AL state name: the text given.
    UnknownState(String),
    /// Not a CiA402 mode of operation (name or number): the text given.
    UnknownMode(String),
    /// Not a PDI route of `trot --pdi`: the text given.
    UnknownPdi(String),
    /// `sweep --shard` that is not `I/N`: the text given.
    BadShard(String),
    /// A fixed-size `--type` that is not the object's size.
    ObjectSize {
        /// Object index.
        index: u16,
        /// Subindex.
        sub: u8,
        /// The object's size in bytes.
        len: usize,
        /// The type given.
        ty: ValueType,
        /// The type's size in bytes.
        size: usize,
    },
    /// `download` without `--type` of an object whose type the slave does not tell.
    TypeUnknown {
        /// Object index.
        index: u16,
        /// Subindex.
        sub: u8,
    },
    /// `reg-read` with a length of 0.
    ZeroLength,
    /// A register range past 0xFFFF.
    BeyondAddressSpace {
        /// The first address.
        address: u16,
        /// The length in bytes.
        len: usize,
    },
    /// `reg-read` with a `--type` whose size is not the length given.
    TypeLength {
        /// The type given.
        ty: ValueType,
        /// Its size in bytes.
        size: usize,
        /// The length given.
        len: u16,
    },
    /// `write` of a process-data input.
    NotAnOutput {
        /// The variable given.
        var: String,
        /// The slave whose input it is.
        position: usize,
    },
    /// An input file that cannot be read.
    UnreadableFile {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// `sii-write` with neither an image file nor `--device`.
    NoImage,
    /// `foe-write` of a path with no file name to send it as, and no `--name`.
    NoFoeName,
    /// An output path that names no file (`/`, `..`).
    NotAFileName(PathBuf),
    /// A `--setpoints` file that is refused: the file and the line's problem.
    Setpoints {
        /// The file.
        path: PathBuf,
        /// What is wrong, with its line.
        error: oxicat_devices::tue_es030::ident::SetpointError,
    },
}

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use UsageError::*;
        match self {
            NotADuration(s) => write!(f, "not a duration: {s:?} (e.g. 400us, 10s)"),
            UnknownTimeUnit { unit, value } => {
                write!(f, "unknown time unit {unit:?} in {value:?}")
            }
            DurationBelowCycle { duration, cycle } => write!(
                f,
                "--duration {duration:?} is shorter than one --cycle {cycle:?}"
            ),
            OutOfRange {
                option,
                value,
                allowed,
            } => write!(f, "{option} {value}: {allowed}"),
            OutOfBounds {
                option,
                value,
                lo,
                hi,
                why,
            } => write!(f, "{option} {value} is not in {lo} … {hi} ({why})"),
            NoGain => f.write_str("--p: give at least one P gain"),
            Sim(e) => write!(f, "--sim: {e}"),
            SimNoDevices(spec) => write!(
                f,
                "--sim {spec:?} names no devices: give NAME:COUNT, e.g. demo:2"
            ),
            NoLink => f.write_str(
                "no network interface: give --iface <if> (or set OXICAT_IFACE), --udp <host:port> for a segment served with `oxicat sim --udp`, or --sim demo:2 for a virtual segment",
            ),
            TimeoutEnv(v) => write!(
                f,
                "OXICAT_TIMEOUT_MS={v:?} is not a number of milliseconds"
            ),
            ZeroTimeout => f.write_str("--timeout must be at least 1 ms"),
            NotAnIndex(s) => write!(f, "not an index/address: {s:?}"),
            NotASubindex(s) => write!(f, "not a subindex: {s:?}"),
            NotAnAlias(s) => write!(f, "not an alias: {s:?} (0 … 0xFFFF)"),
            NotAPassword(s) => write!(f, "not a password (u32): {s:?}"),
            UnknownState(s) => write!(
                f,
                "unknown state {s:?}; one of INIT, PREOP, SAFEOP, OP, BOOT"
            ),
            UnknownMode(s) => write!(f, "unknown mode {s:?}"),
            UnknownPdi(s) => write!(f, "--pdi {s}: direct, lan9252 or et1100"),
            BadShard(s) => write!(f, "--shard {s}: expected I/N, e.g. 2/8"),
            ObjectSize {
                index,
                sub,
                len,
                ty,
                size,
            } => write!(
                f,
                "0x{index:04X}:{sub:02X} holds {len} byte(s), type {ty} is {size}: give the object's type (or none)"
            ),
            TypeUnknown { index, sub } => write!(
                f,
                "the type of 0x{index:04X}:{sub:02X} is not known from the slave; give --type ({})",
                ValueType::NAMES
            ),
            ZeroLength => f.write_str("length 0: give 1 … 65536 bytes"),
            BeyondAddressSpace { address, len } => write!(
                f,
                "0x{address:04X} + {len} bytes ends at 0x{:05X}, beyond the ESC's address space (registers and process RAM end at 0xFFFF)",
                usize::from(*address) + len
            ),
            TypeLength { ty, size, len } => write!(
                f,
                "type {ty} is {size} byte(s), the length given is {len}: give one of them, or both alike"
            ),
            NotAnOutput { var, position } => write!(
                f,
                "{var} is an input (TxPDO) of slave {position}; only outputs can be written"
            ),
            UnreadableFile { path, error } => {
                write!(f, "cannot read {}: {error}", path.display())
            }
            NoImage => f.write_str("give an image file or --device <name>"),
            NoFoeName => f.write_str("give --name"),
            NotAFileName(p) => write!(f, "{} is not a file name", p.display()),
            Setpoints { path, error } => write!(f, "--setpoints {}: {error}", path.display()),
        }
    }
}

impl std::error::Error for UsageError {}

#[cfg(test)]
mod tests {
    use super::UsageError::*;
    use super::*;

    /// Each message as the CLI printed it before the typed errors (the `format!` strings
    /// they replace), so the move changed no text a user or a script sees.
    #[test]
    fn messages_are_the_ones_users_saw() {
        let cases: Vec<(UsageError, &str)> = vec![
            (
                NotADuration("4x".into()),
                "not a duration: \"4x\" (e.g. 400us, 10s)",
            ),
            (
                UnknownTimeUnit {
                    unit: "h".into(),
                    value: "2h".into(),
                },
                "unknown time unit \"h\" in \"2h\"",
            ),
            (
                DurationBelowCycle {
                    duration: Duration::from_micros(500),
                    cycle: Duration::from_millis(1),
                },
                "--duration 500µs is shorter than one --cycle 1ms",
            ),
            (
                OutOfRange {
                    option: "--joints",
                    value: 0.to_string(),
                    allowed: "1 … 64 drives (the master's group holds 64)".into(),
                },
                "--joints 0: 1 … 64 drives (the master's group holds 64)",
            ),
            (
                OutOfRange {
                    option: "--duration",
                    value: 4000.5f64.to_string(),
                    allowed: "0…3600 s".into(),
                },
                "--duration 4000.5: 0…3600 s",
            ),
            (
                OutOfRange {
                    option: "--jobs",
                    value: 0.to_string(),
                    allowed: "at least 1".into(),
                },
                "--jobs 0: at least 1",
            ),
            (
                OutOfBounds {
                    option: "--i",
                    value: f32::NAN.to_string(),
                    lo: 0.0f32.to_string(),
                    hi: 1000.0f32.to_string(),
                    why: "current-loop I gain",
                },
                "--i NaN is not in 0 … 1000 (current-loop I gain)",
            ),
            (
                OutOfBounds {
                    option: "--p",
                    value: 0.001f32.to_string(),
                    lo: 0.01f32.to_string(),
                    hi: 1000.0f32.to_string(),
                    why: "current-loop P gain, V/A",
                },
                "--p 0.001 is not in 0.01 … 1000 (current-loop P gain, V/A)",
            ),
            (NoGain, "--p: give at least one P gain"),
            (
                SimNoDevices(" ".into()),
                "--sim \" \" names no devices: give NAME:COUNT, e.g. demo:2",
            ),
            (
                TimeoutEnv("fast".into()),
                "OXICAT_TIMEOUT_MS=\"fast\" is not a number of milliseconds",
            ),
            (ZeroTimeout, "--timeout must be at least 1 ms"),
            (NotAnIndex("0x1z".into()), "not an index/address: \"0x1z\""),
            (NotASubindex("256".into()), "not a subindex: \"256\""),
            (NotAnAlias("-1".into()), "not an alias: \"-1\" (0 … 0xFFFF)"),
            (NotAPassword("x".into()), "not a password (u32): \"x\""),
            (
                UnknownState("RUN".into()),
                "unknown state \"RUN\"; one of INIT, PREOP, SAFEOP, OP, BOOT",
            ),
            (UnknownMode("fast".into()), "unknown mode \"fast\""),
            (
                UnknownPdi("spi".into()),
                "--pdi spi: direct, lan9252 or et1100",
            ),
            (BadShard("3".into()), "--shard 3: expected I/N, e.g. 2/8"),
            (
                ObjectSize {
                    index: 0x1018,
                    sub: 1,
                    len: 4,
                    ty: ValueType::U8,
                    size: 1,
                },
                "0x1018:01 holds 4 byte(s), type u8 is 1: give the object's type (or none)",
            ),
            (
                TypeUnknown {
                    index: 0x6040,
                    sub: 0,
                },
                "the type of 0x6040:00 is not known from the slave; give --type (bool, u8, u16, u32, u64, i8, i16, i32, i64, f32, f64, string, hex)",
            ),
            (ZeroLength, "length 0: give 1 … 65536 bytes"),
            (
                BeyondAddressSpace {
                    address: 0xFFFF,
                    len: 2,
                },
                "0xFFFF + 2 bytes ends at 0x10001, beyond the ESC's address space (registers and process RAM end at 0xFFFF)",
            ),
            (
                TypeLength {
                    ty: ValueType::U32,
                    size: 4,
                    len: 1,
                },
                "type u32 is 4 byte(s), the length given is 1: give one of them, or both alike",
            ),
            (
                NotAnOutput {
                    var: "0.Counter".into(),
                    position: 0,
                },
                "0.Counter is an input (TxPDO) of slave 0; only outputs can be written",
            ),
            (
                UnreadableFile {
                    path: "img.bin".into(),
                    error: std::io::Error::from(std::io::ErrorKind::NotFound),
                },
                "cannot read img.bin: entity not found",
            ),
            (NoImage, "give an image file or --device <name>"),
            (NoFoeName, "give --name"),
            (NotAFileName("..".into()), ".. is not a file name"),
        ];
        for (e, want) in cases {
            assert_eq!(e.to_string(), want, "{e:?}");
        }
        assert_eq!(
            Sim(SimError::NoDevices).to_string(),
            format!("--sim: {}", SimError::NoDevices)
        );
        assert!(NoLink.to_string().starts_with(
            "no network interface: give --iface <if> (or set OXICAT_IFACE), --udp <host:port>"
        ));
    }
}

//! `oxicat-devices`: the firmware applications of oxicat, each an [`oxicat_slave::Application`]
//! plus its one static [`oxicat_slave::DeviceDef`] (from which the object dictionary, the ESI
//! and the SII are all derived). Hardware is reached only through small traits.
//!
//! Devices: [`demo`] (the thesis' generic "EtherCAT Application", Table 2-2) and its
//! variant [`demo::additions`] (the thesis' section 6.7 change, as one edit).
#![cfg_attr(not(feature = "bench"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[doc(hidden)]
pub use oxicat_slave as __slave;

pub mod axis_hub;
pub mod cia402;
pub mod demo;
pub mod laelaps;
#[cfg(feature = "bench")]
pub mod registry;
#[cfg(feature = "bench")]
pub mod saved;
#[cfg(feature = "bench")]
pub mod twin;

/// A CSV written in memory by the `csv` crate (which joins the fields and quotes those
/// that need it; their formatting is the caller's), as text.
#[cfg(feature = "bench")]
pub(crate) fn csv_text(rows: impl IntoIterator<Item = Vec<String>>) -> Result<String, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.write_record(&r)?;
    }
    let b = w
        .into_inner()
        .map_err(|e| csv::Error::from(e.into_error()))?;
    Ok(String::from_utf8(b).expect("UTF-8 fields give UTF-8"))
}
#[cfg(feature = "toy")]
pub mod toy;
pub mod tue_es030;

/// Declares a device's process data once — record, entry, CoE type, and optionally its
/// physical scaling and unit and a firmware handle name — and generates, in the current
/// module:
///
/// - `OBJECTS`: the records (inputs 0x6xxx, then outputs 0x7xxx), each entry with its
///   [`Scale`](oxicat_slave::Scale) (what SDO users and the master's recordings see);
/// - `RX_PDOS`, `TX_PDOS`: the mappings, entry sizes taken from the types;
///   `RX_ASSIGN`, `TX_ASSIGN`: every PDO assigned, in order;
/// - `OUTPUT_BYTES`, `INPUT_BYTES`: the SM2/SM3 sizes of that assignment; `IMAGE`: the
///   object image size;
/// - `PdVars` and its value `VARS`: the firmware's typed handles (`Var<i16>` for an
///   `Int16`) on every entry that names one (`=> field`), computed when the crate builds
///   ([`Var::of`](oxicat_slave::Var::of)).
///
/// Devices whose records repeat per channel or carry arrays of samples (the TUeES030's three
/// motors and 22 FRF samples, the hub's 15 temperatures) declare their `OBJECTS` with
/// `const fn`s instead, and their handles with [`Var::across`](oxicat_slave::Var::across) /
/// [`Var::subs`](oxicat_slave::Var::subs): the same build-time offsets and type checks.
///
/// An entry is `sub "Name": Type`, then optionally `["unit" / den]` (the integer is
/// `value × den`), then optionally `=> field`.
///
/// ```
/// mod io {
///     oxicat_devices::pd_table! {
///         tx { 0x1A00 "Inputs" { 0x6000 "Inputs" { 1 "Angle": Int16 ["deg" / 100] => angle } } }
///         rx { 0x1600 "Outputs" { 0x7000 "Outputs" { 1 "Out1": Int16, 2 "Out2": Bool => out2 } } }
///     }
/// }
/// assert_eq!(io::OBJECTS.len(), 2);
/// assert_eq!(io::RX_PDOS[0].entries.len(), 2);
/// assert_eq!((io::OUTPUT_BYTES, io::INPUT_BYTES), (3, 2));
/// assert_eq!(io::OBJECTS[0].entries[1].scale().unwrap().unit, "deg");
/// ```
#[macro_export]
macro_rules! pd_table {
    (
        tx { $( $tpdo:literal $tpname:literal {
            $( $tidx:literal $trec:literal { $(
                $tsub:literal $tname:literal : $tty:ident
                $( [ $tunit:literal / $tden:literal ] )?
                $( => $tfield:ident )?
            ),* $(,)? } )*
        } )* }
        rx { $( $rpdo:literal $rpname:literal {
            $( $ridx:literal $rrec:literal { $(
                $rsub:literal $rname:literal : $rty:ident
                $( [ $runit:literal / $rden:literal ] )?
                $( => $rfield:ident )?
            ),* $(,)? } )*
        } )* }
    ) => {
        use $crate::__slave::{
            Access as __A, DataType as __T, EntryDef as __E, ObjectCode as __C,
            ObjectDef as __O, PdoDef as __P, PdoEntry as __PE, PdoMapping as __M,
        };
        /// Process-data records (inputs 0x6xxx, then outputs 0x7xxx).
        pub static OBJECTS: &[__O] = &[
            $( $( __O {
                index: $tidx,
                name: $trec,
                code: __C::Record,
                entries: &[
                    __E::new(0, "SubIndex 000", __T::Unsigned8, __A::RO),
                    $( __E::new($tsub, $tname, __T::$tty, __A::RO).pdo(__M::Tx)
                        $( .limits(&$crate::__slave::Limits::scale(
                            &$crate::__slave::Scale { unit: $tunit, num: 1, den: $tden })) )? ),*
                ],
            }, )* )*
            $( $( __O {
                index: $ridx,
                name: $rrec,
                code: __C::Record,
                entries: &[
                    __E::new(0, "SubIndex 000", __T::Unsigned8, __A::RO),
                    $( __E::new($rsub, $rname, __T::$rty, __A::RW).pdo(__M::Rx)
                        $( .limits(&$crate::__slave::Limits::scale(
                            &$crate::__slave::Scale { unit: $runit, num: 1, den: $rden })) )? ),*
                ],
            }, )* )*
        ];
        /// Object image size of [`OBJECTS`].
        pub const IMAGE: usize = $crate::__slave::image_size(OBJECTS);
        /// TxPDOs (inputs).
        pub static TX_PDOS: &[__P] = &[ $( __P {
            index: $tpdo,
            name: $tpname,
            entries: &[ $( $( __PE::of(OBJECTS, $tidx, $tsub) ),* ),* ],
            configurable: false,
        } ),* ];
        /// RxPDOs (outputs).
        pub static RX_PDOS: &[__P] = &[ $( __P {
            index: $rpdo,
            name: $rpname,
            entries: &[ $( $( __PE::of(OBJECTS, $ridx, $rsub) ),* ),* ],
            configurable: false,
        } ),* ];
        /// Default TxPDO assignment (0x1C13).
        pub static TX_ASSIGN: &[u16] = &[ $( $tpdo ),* ];
        /// Default RxPDO assignment (0x1C12).
        pub static RX_ASSIGN: &[u16] = &[ $( $rpdo ),* ];
        /// Output (RxPDO) process data bytes of the default assignment (SM2).
        pub const OUTPUT_BYTES: usize = $crate::__slave::pdo_bytes(RX_PDOS, RX_ASSIGN);
        /// Input (TxPDO) process data bytes of the default assignment (SM3).
        pub const INPUT_BYTES: usize = $crate::__slave::pdo_bytes(TX_PDOS, TX_ASSIGN);

        /// Typed handles on the process-data entries that name one ([`VARS`]): offsets
        /// into the object image, computed from the declaration when the crate builds.
        #[derive(Debug, Clone, Copy)]
        pub struct PdVars {
            $( $( $( $(
                #[doc = concat!("`", stringify!($tidx), ":", stringify!($tsub), "` ", $tname, " (input).")]
                pub $tfield: $crate::__slave::Var<$crate::__slave::od::ty::$tty>,
            )? )* )* )*
            $( $( $( $(
                #[doc = concat!("`", stringify!($ridx), ":", stringify!($rsub), "` ", $rname, " (output).")]
                pub $rfield: $crate::__slave::Var<$crate::__slave::od::ty::$rty>,
            )? )* )* )*
        }

        /// The handles of [`PdVars`], valid for a dictionary built on a definition
        /// whose `objects` is [`OBJECTS`].
        pub const VARS: PdVars = PdVars {
            $( $( $( $( $tfield: $crate::__slave::Var::of(OBJECTS, $tidx, $tsub), )? )* )* )*
            $( $( $( $( $rfield: $crate::__slave::Var::of(OBJECTS, $ridx, $rsub), )? )* )* )*
        };
    };
}

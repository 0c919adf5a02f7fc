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

/// Declares process-data records and their PDOs in one table and generates, in the
/// current module, `OBJECTS` (records, inputs then outputs, index order), `RX_PDOS`,
/// `TX_PDOS`, `RX_ASSIGN`, `TX_ASSIGN` (every PDO assigned, in order) and `IMAGE` (the
/// object image size). Each PDO maps the records listed in it, entry by entry.
///
/// ```
/// mod io {
///     oxicat_devices::pd_table! {
///         tx { 0x1A00 "Inputs" { 0x6000 "Inputs" { 1 "In1": Int16 } } }
///         rx { 0x1600 "Outputs" { 0x7000 "Outputs" { 1 "Out1": Int16, 2 "Out2": Bool } } }
///     }
/// }
/// assert_eq!(io::OBJECTS.len(), 2);
/// assert_eq!(io::RX_PDOS[0].entries.len(), 2);
/// ```
#[macro_export]
macro_rules! pd_table {
    (
        tx { $( $tpdo:literal $tpname:literal {
            $( $tidx:literal $trec:literal { $( $tsub:literal $tname:literal : $tty:ident ),* $(,)? } )*
        } )* }
        rx { $( $rpdo:literal $rpname:literal {
            $( $ridx:literal $rrec:literal { $( $rsub:literal $rname:literal : $rty:ident ),* $(,)? } )*
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
                    $( __E::new($tsub, $tname, __T::$tty, __A::RO).pdo(__M::Tx) ),*
                ],
            }, )* )*
            $( $( __O {
                index: $ridx,
                name: $rrec,
                code: __C::Record,
                entries: &[
                    __E::new(0, "SubIndex 000", __T::Unsigned8, __A::RO),
                    $( __E::new($rsub, $rname, __T::$rty, __A::RW).pdo(__M::Rx) ),*
                ],
            }, )* )*
        ];
        /// Object image size of [`OBJECTS`].
        pub const IMAGE: usize = $crate::__slave::image_size(OBJECTS);
        /// TxPDOs (inputs).
        pub static TX_PDOS: &[__P] = &[ $( __P {
            index: $tpdo,
            name: $tpname,
            entries: &[ $( $( __PE::new($tidx, $tsub, __T::$tty.bits() as u8) ),* ),* ],
            configurable: false,
        } ),* ];
        /// RxPDOs (outputs).
        pub static RX_PDOS: &[__P] = &[ $( __P {
            index: $rpdo,
            name: $rpname,
            entries: &[ $( $( __PE::new($ridx, $rsub, __T::$rty.bits() as u8) ),* ),* ],
            configurable: false,
        } ),* ];
        /// Default TxPDO assignment (0x1C13).
        pub static TX_ASSIGN: &[u16] = &[ $( $tpdo ),* ];
        /// Default RxPDO assignment (0x1C12).
        pub static RX_ASSIGN: &[u16] = &[ $( $rpdo ),* ];
    };
}

//! oxicat's test kit (not published).
//!
//! The slave stack's firmware reaches its ESC through a [`Pdi`](oxicat_slave::Pdi): on the
//! simulator the software ESC itself, on a board an SPI chip driver. This crate runs the
//! *same* tests over every such path:
//!
//! - [`Port`]: how the firmware reaches the ESC. [`ports::Soft`] is the software ESC as
//!   its own PDI; [`ports::Lan`], [`ports::LanFast`], [`ports::Et2`], [`ports::Et3`] and
//!   [`ports::EtPause`] are `oxicat-pdi`'s LAN9252 and ET1100 drivers talking to the
//!   byte-exact simulated chips of `oxicat_pdi::sim` at 20 MHz SCLK, in front of a
//!   software ESC.
//! - [`Bench`]: a master's side of that ESC (single datagrams, ESM requests, SM setup,
//!   mailbox, an SDO client with segmented transfers) and the stack polled between frames.
//! - [`device`]: the stack's test device (every data type, a 1100-byte blob, PDOs).
//! - [`laelaps`]: the Laelaps II leg node brought to OP in DC mode at 400 µs.
//! - [`every_pdi!`]: instantiates generic test functions once per port.
//!
//! ```ignore
//! fn walks_to_op<P: Port>() {
//!     let mut b = Bench::<P>::new();
//!     b.enter_op();
//! }
//! oxicat_testkit::every_pdi!(walks_to_op);
//! ```
//! makes `soft_esc::walks_to_op`, `lan9252::walks_to_op`, … one `#[test]` each.

pub mod bench;
pub mod device;
pub mod laelaps;
pub mod ports;
pub mod served;

pub use bench::Bench;
pub use ports::Port;

/// Runs a test body on a thread with a large stack (an ethercrab master is big in a debug
/// build) and passes its panic on.
pub fn big<F: FnOnce() + Send + 'static>(f: F) {
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap_or_else(|e| std::panic::resume_unwind(e));
}

/// Instantiates each generic test function `f::<P: Port>()` once per PDI path, as a
/// `#[test]` in a module named after the path: `soft_esc`, `lan9252`, `lan9252_fast_read`,
/// `et1100`, `et1100_three_byte`, `et1100_read_pause`.
#[macro_export]
macro_rules! every_pdi {
    ($($f:ident),* $(,)?) => {
        $crate::every_pdi!(@port soft_esc, $crate::ports::Soft, $($f),*);
        $crate::every_pdi!(@port lan9252, $crate::ports::Lan, $($f),*);
        $crate::every_pdi!(@port lan9252_fast_read, $crate::ports::LanFast, $($f),*);
        $crate::every_pdi!(@port et1100, $crate::ports::Et2, $($f),*);
        $crate::every_pdi!(@port et1100_three_byte, $crate::ports::Et3, $($f),*);
        $crate::every_pdi!(@port et1100_read_pause, $crate::ports::EtPause, $($f),*);
    };
    (@port $m:ident, $p:ty, $($f:ident),*) => {
        mod $m {
            $(
                #[test]
                fn $f() {
                    super::$f::<$p>();
                }
            )*
        }
    };
}

#[cfg(test)]
mod tests {
    use super::ports::*;
    use super::*;

    /// The driver ports really carry the stack's PDI traffic over SPI; the software ESC has
    /// no bus.
    fn traffic<P: Port>() -> Option<(u64, u64)> {
        let mut b = Bench::<P>::new();
        b.port.reset_bus_stats();
        b.enter_op();
        b.bus_stats().map(|s| (s.transactions, s.bytes))
    }

    #[test]
    fn drivers_carry_the_traffic() {
        assert_eq!(traffic::<Soft>(), None);
        for (name, t) in [
            ("lan", traffic::<Lan>()),
            ("lan fast", traffic::<LanFast>()),
            ("et 2", traffic::<Et2>()),
            ("et 3", traffic::<Et3>()),
            ("et pause", traffic::<EtPause>()),
        ] {
            let (n, bytes) = t.unwrap();
            // ESM to OP with SDO uploads: dozens of PDI accesses at least.
            assert!(
                n > 50 && bytes > 4 * n,
                "{name}: {n} transactions, {bytes} bytes"
            );
        }
    }

    /// A malformed SPI frame seen by the chip fails the bench when it ends.
    #[test]
    #[should_panic(expected = "LAN9252")]
    fn protocol_errors_fail_the_bench() {
        use embedded_hal::spi::SpiDevice;
        let b = Bench::<Lan>::new();
        // An unknown SPI instruction byte.
        let mut spi = b.port.h.spi();
        spi.write(&[0x5A, 0, 0]).unwrap();
        drop(b);
    }
}

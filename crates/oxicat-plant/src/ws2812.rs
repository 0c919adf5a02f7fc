//! A WS2812B LED chain that decodes the bit stream a PWM timer produces (one duty value per
//! bit period) back into colours, checking each bit against the datasheet timing: T0H
//! 0.4 µs, T1H 0.8 µs, T0L 0.85 µs, T1L 0.45 µs, each ±150 ns; a low time of at least 50 µs
//! latches. A bit whose high or low time is outside the tolerance is flagged (a real LED
//! would read it either way or lose sync).

/// Nominal high time of a 0 \[ns\].
pub const T0H_NS: f64 = 400.0;
/// Nominal high time of a 1 \[ns\].
pub const T1H_NS: f64 = 800.0;
/// Nominal low time of a 0 \[ns\].
pub const T0L_NS: f64 = 850.0;
/// Nominal low time of a 1 \[ns\].
pub const T1L_NS: f64 = 450.0;
/// Tolerance on every high and low time \[ns\].
pub const TOL_NS: f64 = 150.0;
/// Minimum low time that latches (reset) \[ns\].
pub const RESET_NS: f64 = 50_000.0;

/// One decoded colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Color {
    /// Red.
    pub r: u8,
    /// Green.
    pub g: u8,
    /// Blue.
    pub b: u8,
}

/// A bit whose timing was out of tolerance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BadBit {
    /// Index of the duty value.
    pub index: usize,
    /// High time \[ns\].
    pub high_ns: f64,
    /// Low time \[ns\].
    pub low_ns: f64,
}

/// What a chain made of one stream.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Decoded {
    /// Colours latched, first LED first.
    pub colors: Vec<Color>,
    /// Bits out of tolerance.
    pub bad_bits: Vec<BadBit>,
    /// True when the stream ended with a valid reset (the colours were latched).
    pub latched: bool,
}

fn within(x: f64, nominal: f64) -> bool {
    (x - nominal).abs() <= TOL_NS
}

/// Decodes `duties` (compare values of a timer with `period` ticks per bit at `clock_hz`)
/// as a chain of `leds` WS2812B would (the first 24 bits go to the first LED, and so on).
pub fn decode(duties: &[u16], clock_hz: f64, period: u16, leds: usize) -> Decoded {
    let tick = 1e9 / clock_hz;
    let bit_ns = period as f64 * tick;
    let mut out = Decoded::default();
    let mut bits: Vec<bool> = Vec::new();
    let mut low_run = 0.0;
    let mut i = 0;
    while i < duties.len() {
        let d = duties[i];
        if d == 0 {
            low_run += bit_ns;
            i += 1;
            continue;
        }
        low_run = 0.0;
        let high = d.min(period) as f64 * tick;
        let low = bit_ns - high;
        // The low time of the last bit before a reset is part of the reset.
        let next_low = duties.get(i + 1).is_none_or(|&n| n == 0);
        let one = (high - T1H_NS).abs() < (high - T0H_NS).abs();
        let ok = if one {
            within(high, T1H_NS) && (next_low || within(low, T1L_NS))
        } else {
            within(high, T0H_NS) && (next_low || within(low, T0L_NS))
        };
        if !ok {
            out.bad_bits.push(BadBit {
                index: i,
                high_ns: high,
                low_ns: low,
            });
        }
        bits.push(one);
        i += 1;
    }
    // The trailing low run latches only if it is long enough.
    let trailing_zero_run = duties.iter().rev().take_while(|&&d| d == 0).count() as f64 * bit_ns;
    out.latched = trailing_zero_run >= RESET_NS;
    let _ = low_run;
    for led in bits.chunks_exact(24).take(leds) {
        let byte = |k: usize| {
            led[k * 8..k * 8 + 8]
                .iter()
                .fold(0u8, |a, &b| a << 1 | b as u8)
        };
        out.colors.push(Color {
            g: byte(0),
            r: byte(1),
            b: byte(2),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nominal_stream_decodes_and_mistimed_bits_are_flagged() {
        // 80 MHz: 100 ticks per bit, T0H 32, T1H 64.
        let mut d: Vec<u16> = Vec::new();
        for byte in [0x10u8, 0x20, 0x30] {
            for k in (0..8).rev() {
                d.push(if byte >> k & 1 != 0 { 64 } else { 32 });
            }
        }
        d.extend([0u16; 48]);
        let r = decode(&d, 80e6, 100, 1);
        assert!(r.latched && r.bad_bits.is_empty());
        assert_eq!(
            r.colors,
            vec![Color {
                g: 0x10,
                r: 0x20,
                b: 0x30
            }]
        );
        // A 0 at 0.6 µs high is 200 ns off nominal: flagged.
        d[1] = 48;
        assert_eq!(decode(&d, 80e6, 100, 1).bad_bits.len(), 1);
        // Too short a reset does not latch.
        let r = decode(&d[..24 + 10], 80e6, 100, 1);
        assert!(!r.latched);
    }
}

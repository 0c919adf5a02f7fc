//! The few `f32` functions the leg firmware needs (`sqrt`, `sin`, `cos`, `atan2`,
//! `floor`, `rem_euclid`), written out because `core` has none of them and the crate
//! takes no math dependency. Algorithms: Newton square root; Cody–Waite reduction to
//! [−π/4, π/4] with Taylor polynomials for sine and cosine; fdlibm's `atanf` reduction and
//! polynomial for the arctangent. Accuracy is a few ulp over the ranges the firmware
//! uses (checked against `std` in the tests), and results are bit-identical on the host
//! and on the microcontroller.

use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// Largest integer not greater than `x`.
pub fn floor(x: f32) -> f32 {
    if x.is_nan() || x.abs() >= 8_388_608.0 {
        return x; // NaN, or already an integer (2^23 and above)
    }
    let i = x as i32 as f32;
    if i > x {
        i - 1.0
    } else {
        i
    }
}

/// Euclidean remainder of `x` by `m > 0`, in `[0, m)`.
pub fn rem_euclid(x: f32, m: f32) -> f32 {
    let r = x - floor(x / m) * m;
    if r < 0.0 {
        r + m
    } else if r >= m {
        r - m
    } else {
        r
    }
}

/// Square root (NaN for negative arguments).
pub fn sqrt(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 || x.is_infinite() {
        return x;
    }
    // Scale subnormals and tiny values into the normal range for the bit estimate.
    let (x, scale) = if x < 1.0e-30 {
        (x * 1.0e30, 1.0e-15)
    } else {
        (x, 1.0)
    };
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1FBD_1DF5);
    for _ in 0..4 {
        y = 0.5 * (y + x / y);
    }
    y * scale
}

/// π/2 split in three parts for the Cody–Waite argument reduction.
const PIO2_1: f32 = 1.570_312_5;
const PIO2_2: f32 = 4.837_513e-4;
const PIO2_3: f32 = 7.549_79e-8;

/// `x = k·π/2 + r` with `|r| <= π/4`; returns `(k mod 4, r)`.
fn reduce(x: f32) -> (i32, f32) {
    let k = floor(x * (2.0 / PI) + 0.5);
    let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
    ((k as i32) & 3, r)
}

fn sin_poly(r: f32) -> f32 {
    let z = r * r;
    r * (1.0 + z * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (-1.0 / 5040.0 + z * (1.0 / 362_880.0)))))
}

fn cos_poly(r: f32) -> f32 {
    let z = r * r;
    1.0 + z
        * (-0.5
            + z * (1.0 / 24.0
                + z * (-1.0 / 720.0 + z * (1.0 / 40_320.0 + z * (-1.0 / 3_628_800.0)))))
}

/// Sine (radians; meant for `|x|` up to a few thousand).
pub fn sin(x: f32) -> f32 {
    if !x.is_finite() {
        return f32::NAN;
    }
    let (q, r) = reduce(x);
    match q {
        0 => sin_poly(r),
        1 => cos_poly(r),
        2 => -sin_poly(r),
        _ => -cos_poly(r),
    }
}

/// Cosine (radians; meant for `|x|` up to a few thousand).
pub fn cos(x: f32) -> f32 {
    if !x.is_finite() {
        return f32::NAN;
    }
    let (q, r) = reduce(x);
    match q {
        0 => cos_poly(r),
        1 => -sin_poly(r),
        2 => -cos_poly(r),
        _ => sin_poly(r),
    }
}

/// Arctangent in (−π/2, π/2) (fdlibm `atanf`).
pub fn atan(x: f32) -> f32 {
    const ATANHI: [f32; 4] = [4.636_476e-1, FRAC_PI_4, 9.827_937e-1, FRAC_PI_2];
    const ATANLO: [f32; 4] = [5.012_158_2e-9, 3.774_895e-8, 3.447_321_7e-8, 7.549_79e-8];
    const AT: [f32; 5] = [
        3.333_332_8e-1,
        -1.999_915_8e-1,
        1.425_363_6e-1,
        -1.064_801_7e-1,
        6.168_760_7e-2,
    ];
    if x.is_nan() {
        return x;
    }
    let neg = x < 0.0;
    let mut a = x.abs();
    if a >= 1.0e8 {
        return if neg { -FRAC_PI_2 } else { FRAC_PI_2 };
    }
    let id: i32;
    if a < 0.4375 {
        if a < 1.0e-6 {
            return x;
        }
        id = -1;
    } else if a < 0.6875 {
        id = 0;
        a = (2.0 * a - 1.0) / (2.0 + a);
    } else if a < 1.1875 {
        id = 1;
        a = (a - 1.0) / (a + 1.0);
    } else if a < 2.4375 {
        id = 2;
        a = (a - 1.5) / (1.0 + 1.5 * a);
    } else {
        id = 3;
        a = -1.0 / a;
    }
    let z = a * a;
    let w = z * z;
    let s1 = z * (AT[0] + w * (AT[2] + w * AT[4]));
    let s2 = w * (AT[1] + w * AT[3]);
    let r = if id < 0 {
        a - a * (s1 + s2)
    } else {
        let i = id as usize;
        ATANHI[i] - ((a * (s1 + s2) - ATANLO[i]) - a)
    };
    if neg {
        -r
    } else {
        r
    }
}

/// Four-quadrant arctangent of `y / x` in (−π, π].
pub fn atan2(y: f32, x: f32) -> f32 {
    if x.is_nan() || y.is_nan() {
        return f32::NAN;
    }
    if x == 0.0 {
        return if y > 0.0 {
            FRAC_PI_2
        } else if y < 0.0 {
            -FRAC_PI_2
        } else {
            0.0
        };
    }
    if y.abs() > x.abs() {
        // Use the reciprocal to keep the quotient bounded.
        let a = atan(x / y);
        let base = if y > 0.0 { FRAC_PI_2 } else { -FRAC_PI_2 };
        return base - a;
    }
    let a = atan(y / x);
    if x > 0.0 {
        a
    } else if y >= 0.0 {
        a + PI
    } else {
        a - PI
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    #[test]
    fn sqrt_matches_std() {
        for i in 0..20_000 {
            let x = i as f32 * 0.013 + 1.0e-6;
            assert!(close(sqrt(x), std::primitive::f32::sqrt(x), 2.0e-7), "{x}");
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert!(sqrt(-1.0).is_nan());
        assert!(close(sqrt(1.0e-38), 1.0e-19, 1.0e-6));
    }

    #[test]
    fn sin_cos_match_std() {
        for i in -200_000..200_000 {
            let x = i as f32 * 1.0e-3;
            assert!(
                (sin(x) - std::primitive::f32::sin(x)).abs() < 3.0e-7,
                "sin {x}"
            );
            assert!(
                (cos(x) - std::primitive::f32::cos(x)).abs() < 3.0e-7,
                "cos {x}"
            );
        }
    }

    #[test]
    fn atan2_matches_std() {
        for i in -300..=300 {
            for j in -300..=300 {
                let (y, x) = (i as f32 * 0.01, j as f32 * 0.0123);
                let e = std::primitive::f32::atan2(y, x);
                assert!((atan2(y, x) - e).abs() < 4.0e-7, "atan2({y}, {x})");
            }
        }
    }

    #[test]
    fn floor_and_rem() {
        assert_eq!(floor(-0.5), -1.0);
        assert_eq!(floor(2.0), 2.0);
        assert_eq!(floor(2.7), 2.0);
        assert!(close(rem_euclid(-0.5, 2.0), 1.5, 1e-7));
        assert!(close(rem_euclid(7.0, 2.0), 1.0, 1e-7));
        let r = rem_euclid(-1.0e-9, 6.283_185_5);
        assert!((0.0..6.283_185_5).contains(&r));
    }
}

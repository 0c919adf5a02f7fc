//! Transmission constants of the Laelaps II joints (thesis §6.10) — the one place where the
//! thesis' gear-ratio contradiction is resolved.

/// Pulley stage after every gearhead: 48/26 reduction (thesis §6.10).
pub const PULLEY_RATIO: f64 = 48.0 / 26.0;

/// Hip gearhead: Maxon GP 52 C, part 223089, ratio 343/8 = 42.875.
pub const HIP_GEARHEAD_RATIO: f64 = 343.0 / 8.0;

/// Knee gearhead: Maxon GP 52 C, part 223090, ratio 637/12 ≈ 53.083.
pub const KNEE_GEARHEAD_RATIO: f64 = 637.0 / 12.0;

/// Total hip reduction, motor to joint: 343/8 · 48/26 = 1029/13 ≈ 79.15.
///
/// **The thesis contradicts itself.** §6.10 (and Table 3-4, the speed-estimate range) give the
/// hip 1029/13 ≈ 79.15 (EC 45 + GP 52 C 343/8) and the knee 98 (RE 50 + GP 52 C 637/12). Its
/// firmware ISRs (`ngwnia1 = raw·8·26/(2000·343·48)` on the knee channel) and the Matlab
/// post-processing (`i_knee = 8·26/(343·48)`) use the ratios the other way round. The
/// hardware list of §6.10 names part numbers per joint, so the plant follows §6.10:
/// hip 79.15, knee 98. A firmware that uses the swapped ratios will report angles that are off
/// by the factor 98/79.15 ≈ 1.24 (knee) and 79.15/98 (hip) against this plant.
pub const HIP_RATIO: f64 = HIP_GEARHEAD_RATIO * PULLEY_RATIO;

/// Total knee reduction, motor to joint: 637/12 · 48/26 = 98 (thesis §6.10; see [`HIP_RATIO`]).
pub const KNEE_RATIO: f64 = KNEE_GEARHEAD_RATIO * PULLEY_RATIO;

/// GP 52 C, 3 stages: maximum efficiency 75 % (Maxon catalogue, GP 52 C data sheet).
///
/// Cross-check: the thesis' "45 Nm after the gearhead" for the knee at 12 A equals
/// 12 A · 91.7 mNm/A · 53.08 · 0.75 = 43.8 Nm, i.e. it is consistent with this efficiency.
pub const GEARHEAD_EFFICIENCY: f64 = 0.75;

/// Timing-belt pulley stage efficiency: 0.95 (plausible value for a toothed belt; not in the thesis).
pub const PULLEY_EFFICIENCY: f64 = 0.95;

/// Torque at which the coupler between gearhead and pulley slips: 30 Nm (thesis §6.11).
pub const COUPLER_SLIP_TORQUE: f64 = 30.0;

//! Thermal nodes for temperature sensors: lumped heat capacities with a thermal resistance
//! to ambient, heated by a current through a winding (motor housing), plus sensors with
//! seeded, deterministic noise and an unplug switch. Fixed-step explicit integration.

/// One lumped thermal mass.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalNode {
    /// Temperature \[°C\].
    pub temp: f64,
    /// Heat capacity \[J/K\].
    pub capacity: f64,
    /// Thermal resistance to ambient \[K/W\].
    pub r_ambient: f64,
    /// Electrical resistance of the winding heating it \[Ω\] (0: not heated).
    pub r_winding: f64,
    /// Current through the winding \[A\].
    pub current: f64,
}

impl ThermalNode {
    /// A node at `temp` with time constant `tau = capacity · r_ambient`.
    pub fn new(temp: f64, capacity: f64, r_ambient: f64) -> Self {
        Self {
            temp,
            capacity,
            r_ambient,
            r_winding: 0.0,
            current: 0.0,
        }
    }

    /// A motor housing: winding resistance `r_winding`, time constant `tau` \[s\],
    /// `r_ambient` \[K/W\].
    pub fn motor(ambient: f64, r_winding: f64, r_ambient: f64, tau: f64) -> Self {
        Self {
            r_winding,
            ..Self::new(ambient, tau / r_ambient, r_ambient)
        }
    }

    /// Time constant \[s\].
    pub fn tau(&self) -> f64 {
        self.capacity * self.r_ambient
    }

    /// Heat input now \[W\] (I²R).
    pub fn power(&self) -> f64 {
        self.current * self.current * self.r_winding
    }

    /// Steady-state temperature at the present current.
    pub fn steady(&self, ambient: f64) -> f64 {
        ambient + self.power() * self.r_ambient
    }
}

/// Thermal nodes around one ambient temperature.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalNet {
    /// Ambient temperature \[°C\].
    pub ambient: f64,
    /// The nodes.
    pub nodes: Vec<ThermalNode>,
    /// Integration step \[s\].
    pub step: f64,
    time: f64,
}

impl ThermalNet {
    /// A net at `ambient` with a 10 ms step.
    pub fn new(ambient: f64, nodes: Vec<ThermalNode>) -> Self {
        Self {
            ambient,
            nodes,
            step: 0.01,
            time: 0.0,
        }
    }

    /// Simulated time \[s\].
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Advances by `dt` seconds in fixed steps (exact exponential per step, stable for any
    /// step).
    pub fn advance(&mut self, dt: f64) {
        let mut left = dt;
        while left > 1e-12 {
            let h = left.min(self.step);
            for n in &mut self.nodes {
                let target = n.steady(self.ambient);
                let k = (-h / n.tau().max(1e-9)).exp();
                n.temp = target + (n.temp - target) * k;
            }
            self.time += h;
            left -= h;
        }
    }
}

/// SplitMix64: small, seeded, deterministic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// Next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in \[0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Approximately normal (sum of 12 uniforms − 6), unit variance.
    pub fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

/// Where a sensor sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mount {
    /// In the air (ambient).
    Ambient,
    /// On thermal node `n`.
    Node(usize),
}

/// A temperature sensor: its mount, a fixed offset, noise, plugged or not.
#[derive(Debug, Clone, PartialEq)]
pub struct TempSensor {
    /// Where it sits.
    pub mount: Mount,
    /// Calibration offset \[K\].
    pub offset: f64,
    /// Noise standard deviation \[K\].
    pub noise: f64,
    /// Plugged into the bus.
    pub plugged: bool,
    rng: Rng,
}

impl TempSensor {
    /// A sensor with noise `noise` \[K\] seeded by `seed`.
    pub fn new(mount: Mount, noise: f64, seed: u64) -> Self {
        Self {
            mount,
            offset: 0.0,
            noise,
            plugged: true,
            rng: Rng::new(seed),
        }
    }

    /// The temperature the sensor's die has now, with noise \[°C\] (the DS18B20 model
    /// quantises it at conversion).
    pub fn sample(&mut self, net: &ThermalNet) -> f64 {
        let t = match self.mount {
            Mount::Ambient => net.ambient,
            Mount::Node(n) => net.nodes.get(n).map_or(net.ambient, |n| n.temp),
        };
        t + self.offset + self.noise * self.rng.normal()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motor_heats_to_steady_state_and_cools_with_its_time_constant() {
        let mut net = ThermalNet::new(25.0, vec![ThermalNode::motor(25.0, 1.0, 2.0, 10.0)]);
        net.nodes[0].current = 10.0; // 100 W × 2 K/W = +200 K
        net.advance(10.0);
        let t = net.nodes[0].temp;
        assert!(
            (t - (25.0 + 200.0 * (1.0 - (-1.0f64).exp()))).abs() < 0.05,
            "{t}"
        );
        net.nodes[0].current = 0.0;
        net.advance(100.0);
        assert!((net.nodes[0].temp - 25.0).abs() < 0.01);
    }

    #[test]
    fn sensor_noise_is_seeded_and_deterministic() {
        let net = ThermalNet::new(20.0, vec![]);
        let mut a = TempSensor::new(Mount::Ambient, 0.1, 7);
        let mut b = TempSensor::new(Mount::Ambient, 0.1, 7);
        let xa: Vec<f64> = (0..100).map(|_| a.sample(&net)).collect();
        let xb: Vec<f64> = (0..100).map(|_| b.sample(&net)).collect();
        assert_eq!(xa, xb);
        let mean = xa.iter().sum::<f64>() / 100.0;
        assert!((mean - 20.0).abs() < 0.05);
        assert!(xa.iter().any(|&x| x != 20.0));
    }
}

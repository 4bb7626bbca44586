//! Battery supervision: the supply voltage, filtered, against an under-voltage cutoff.
//!
//! The shell samples the board's battery-sense ADC every control step and passes millivolts in
//! [`crate::Inputs::battery_mv`] (0 = this board does not measure it: the monitor then never
//! trips, and the status reports 0). The monitor low-pass filters the reading (first order, time
//! constant [`BatteryConfig::filter_time_us`]) so the sag of an acceleration (the pack's internal
//! resistance times up to 4 x 10 A) does not trip it, and reports `BATTERY_LOW` while the
//! filtered voltage is below the cutoff, until it recovers above cutoff + hysteresis. The machine
//! ramps a moving robot to zero when it trips and refuses drive commands while it holds: a LiPo
//! pack run below ~3.3 V per cell is damaged, and a robot whose voltage collapses mid-run under a
//! car is worse off than one that stopped in a controlled way.

/// Battery supervision settings (built into the firmware; not on the MCU link).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryConfig {
    /// Filtered voltage below which `BATTERY_LOW` is raised, mV (0 disables the monitor).
    /// Default 19.8 V: 3.3 V per cell of a 6S pack (the RoboMaster TB47D the C620s run from).
    pub cutoff_mv: u16,
    /// `BATTERY_LOW` clears above `cutoff_mv + hysteresis_mv`.
    pub hysteresis_mv: u16,
    /// Time constant of the low-pass filter, microseconds.
    pub filter_time_us: u64,
}

impl Default for BatteryConfig {
    fn default() -> Self {
        Self {
            cutoff_mv: 19_800,
            hysteresis_mv: 600,
            filter_time_us: 1_000_000,
        }
    }
}

/// RoboMaster Development Board C: the battery input reaches PF10 (ADC3 channel 8) through a
/// 200 kOhm / 22 kOhm divider (DJI's reference firmware scales by 222 / 22 = 10.09), with a
/// 3.3 V reference and 12-bit conversions. Approximate: resistor tolerance and the reference
/// make it good to about 2 %; calibrate `DIVIDER_NUM / DIVIDER_DEN` against a meter per board.
pub const DIVIDER_NUM: u32 = 222;
/// See [`DIVIDER_NUM`].
pub const DIVIDER_DEN: u32 = 22;
/// ADC reference, mV.
pub const ADC_REF_MV: u32 = 3_300;
/// Full scale of a 12-bit conversion.
pub const ADC_FULL_SCALE: u32 = 4_095;

/// Battery millivolts from a raw 12-bit ADC3 reading of the board's divider (saturating).
pub fn adc_to_mv(raw: u16) -> u16 {
    let raw = u32::from(raw).min(ADC_FULL_SCALE);
    let mv = raw * ADC_REF_MV * DIVIDER_NUM / (ADC_FULL_SCALE * DIVIDER_DEN);
    u16::try_from(mv).unwrap_or(u16::MAX)
}

/// The filtered voltage and the `BATTERY_LOW` state (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatteryMonitor {
    filtered_mv: Option<f32>,
    last_us: Option<u64>,
    low: bool,
}

impl Default for BatteryMonitor {
    fn default() -> Self {
        Self::new()
    }
}

impl BatteryMonitor {
    /// No reading yet.
    pub const fn new() -> Self {
        Self {
            filtered_mv: None,
            last_us: None,
            low: false,
        }
    }

    /// Takes one reading at `now_us` (0 = not measured: ignored).
    pub fn update(&mut self, config: &BatteryConfig, mv: u16, now_us: u64) {
        if mv == 0 {
            return;
        }
        let x = f32::from(mv);
        let filtered = match (self.filtered_mv, self.last_us) {
            (Some(y), Some(last)) => {
                #[allow(clippy::cast_precision_loss)]
                let dt = now_us.saturating_sub(last) as f32;
                #[allow(clippy::cast_precision_loss)]
                let tau = config.filter_time_us.max(1) as f32;
                // Exact first-order step for any dt, so a late step does not overshoot.
                let alpha = 1.0 - libm::expf(-dt / tau);
                y + alpha * (x - y)
            }
            // The first reading starts the filter (a freshly booted board is not "low" for a second).
            _ => x,
        };
        self.filtered_mv = Some(filtered);
        self.last_us = Some(now_us);
        if config.cutoff_mv == 0 {
            self.low = false;
        } else if filtered < f32::from(config.cutoff_mv) {
            self.low = true;
        } else if filtered > f32::from(config.cutoff_mv) + f32::from(config.hysteresis_mv) {
            self.low = false;
        }
    }

    /// Below the cutoff (and not yet recovered above cutoff + hysteresis).
    pub fn is_low(&self) -> bool {
        self.low
    }

    /// The filtered voltage, mV (0 until the first reading).
    pub fn filtered_mv(&self) -> u16 {
        self.filtered_mv.map_or(0, |v| {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let mv = libm::roundf(v).clamp(0.0, f32::from(u16::MAX)) as u16;
            mv
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STEP_US: u64 = 1_000;

    fn run(m: &mut BatteryMonitor, c: &BatteryConfig, mv: u16, from_us: u64, steps: u64) -> u64 {
        for k in 0..steps {
            m.update(c, mv, from_us + k * STEP_US);
        }
        from_us + steps * STEP_US
    }

    #[test]
    fn the_board_divider_maps_full_scale_and_a_full_pack() {
        assert_eq!(adc_to_mv(0), 0);
        // Full scale: 3.3 V * 222 / 22 = 33.3 V.
        assert_eq!(adc_to_mv(4_095), 33_300);
        assert_eq!(adc_to_mv(u16::MAX), 33_300);
        // A full 6S pack (25.2 V) reads 25.2 / 33.3 * 4095 = 3099.
        assert!((i32::from(adc_to_mv(3_099)) - 25_200).abs() <= 10);
    }

    #[test]
    fn a_short_sag_does_not_trip_but_a_flat_pack_does_within_the_filter_time() {
        let c = BatteryConfig::default();
        let mut m = BatteryMonitor::new();
        let t = run(&mut m, &c, 24_000, 0, 100);
        assert!(!m.is_low());
        // 200 ms at 18 V (acceleration sag): the filter stays above 19.8 V.
        let t = run(&mut m, &c, 18_000, t, 200);
        assert!(!m.is_low(), "filtered {} mV", m.filtered_mv());
        let t = run(&mut m, &c, 24_000, t, 500);
        // A pack at 19 V: below the cutoff after about tau * ln(5000 / 800) = 1.8 s.
        let mut tripped_after = None;
        for k in 0..5_000 {
            m.update(&c, 19_000, t + k * STEP_US);
            if m.is_low() {
                tripped_after = Some(k);
                break;
            }
        }
        let k = tripped_after.expect("trips");
        assert!((1_500..2_200).contains(&k), "tripped after {k} ms");
    }

    #[test]
    fn it_clears_only_above_the_hysteresis() {
        let c = BatteryConfig::default();
        let mut m = BatteryMonitor::new();
        let t = run(&mut m, &c, 19_000, 0, 10);
        assert!(m.is_low(), "the first reading starts the filter");
        // 20.2 V: above the cutoff, below cutoff + 600 mV: still low.
        let t = run(&mut m, &c, 20_200, t, 10_000);
        assert!(m.is_low());
        run(&mut m, &c, 20_600, t, 10_000);
        assert!(!m.is_low());
    }

    #[test]
    fn unmeasured_or_disabled_never_trips() {
        let c = BatteryConfig::default();
        let mut m = BatteryMonitor::new();
        run(&mut m, &c, 0, 0, 1_000);
        assert!(!m.is_low());
        assert_eq!(m.filtered_mv(), 0);
        let off = BatteryConfig { cutoff_mv: 0, ..c };
        run(&mut m, &off, 5_000, 0, 1_000);
        assert!(!m.is_low());
        assert_eq!(m.filtered_mv(), 5_000);
    }
}

//! The MCU's clock on the host's: when was an odometry report measured, in host time?
//!
//! The firmware stamps each report with its own clock (`stamp_us`, microseconds since boot); the
//! service sees it when the serial read returns. The receive time is late by the UART transfer,
//! the USB-serial adapter's latency timer and the service loop's wait, and reports read in one
//! loop iteration share one receive time. Stamping odometry with its receive time made the
//! pipeline drop the second of two reports read together ("not after the previous one") and put
//! up to one loop period of jitter on every wheel pose.
//!
//! [`McuClockMap`] is the passive one-way synchronisation of Olson ("A passive solution to the
//! sensor synchronization problem", IROS 2010): the offset `host - mcu` is the smallest
//! `rx - stamp` seen so far, because a report can arrive late but never before it was sent. The
//! smallest observed latency is taken as zero (the fixed part of the latency, about a
//! millisecond for 80 bytes at 1 Mbaud, is left in; it is common to all reports). The offset may
//! rise by at most [`DRIFT_ALLOWANCE_PPM`] of the MCU time elapsed, so a slow MCU crystal (the
//! STM32's HSE is a +/-20 ppm part) is followed while a burst of late reports barely moves it.
//! A report whose MCU stamp goes backwards means the MCU rebooted: the map starts over.
//!
//! Pure: stamps in, stamps out; the same sequence of reports gives the same stamps live and in a
//! replay of the recording (which keeps both clocks: `odometry.csv` has `wall_us` and `mcu_us`).

/// How fast the offset may grow, parts per million of MCU time: more than a crystal's drift,
/// far less than a late report's delay.
pub const DRIFT_ALLOWANCE_PPM: i128 = 200;

/// Maps MCU stamps to host wall-clock microseconds. See the module docs.
#[derive(Debug, Clone, Default)]
pub struct McuClockMap {
    /// `host - mcu`, microseconds, once a report has been seen.
    offset_us: Option<i128>,
    last_mcu_us: u64,
    last_host_us: u64,
    resets: u32,
}

impl McuClockMap {
    /// A map that has seen nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The host time at which the report stamped `mcu_us` by the MCU was measured, given that it
    /// was received at `rx_host_us`. Strictly increasing over calls, and never later than the
    /// receive time except where a tie is moved 1 us on (the second of two reports read together
    /// while the offset is still being learnt from them).
    pub fn map(&mut self, rx_host_us: u64, mcu_us: u64) -> u64 {
        let observed = i128::from(rx_host_us) - i128::from(mcu_us);
        let offset = match self.offset_us {
            Some(o) if mcu_us >= self.last_mcu_us => {
                let rise_limit =
                    i128::from(mcu_us - self.last_mcu_us) * DRIFT_ALLOWANCE_PPM / 1_000_000;
                if observed < o {
                    observed
                } else {
                    o + (observed - o).min(rise_limit)
                }
            }
            Some(_) => {
                // The MCU's clock went backwards: it rebooted.
                self.resets += 1;
                observed
            }
            None => observed,
        };
        self.offset_us = Some(offset);
        self.last_mcu_us = mcu_us;
        let host = u64::try_from(i128::from(mcu_us) + offset).unwrap_or(rx_host_us);
        // A tie (two reports of one read, while the offset is still being learnt) is moved on.
        let host = host.max(self.last_host_us.saturating_add(1));
        self.last_host_us = host;
        host
    }

    /// How many times the MCU's clock went backwards (reboots) and the map started over.
    pub fn resets(&self) -> u32 {
        self.resets
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const BASE_US: u64 = 1_790_000_000_000_000;

    #[test]
    fn late_reports_are_moved_back_to_when_they_were_measured() {
        // Reports every 10 ms; the first arrives 7 ms late, the second 1 ms late, then a batch
        // of two read together 30 ms late.
        let mut m = McuClockMap::new();
        let t = |mcu_ms: u64| mcu_ms * 1_000;
        assert_eq!(m.map(BASE_US + t(17), t(10)), BASE_US + t(17));
        assert_eq!(m.map(BASE_US + t(21), t(20)), BASE_US + t(21));
        let a = m.map(BASE_US + t(60), t(30));
        let b = m.map(BASE_US + t(60), t(40));
        // Both on the MCU's clock, 1 ms (the smallest latency seen) after their measurement,
        // plus the drift allowance of 2 us per 10 ms the late pair may lift the offset by.
        assert_eq!((a, b), (BASE_US + t(31) + 2, BASE_US + t(41) + 4));
    }

    #[test]
    fn a_slow_mcu_clock_is_followed_and_a_reboot_starts_over() {
        // The MCU's clock runs 50 ppm slow; reports arrive exactly 1 ms after measurement.
        let mut m = McuClockMap::new();
        let mut worst = 0_i64;
        for k in 0..60_000_u64 {
            let host = BASE_US + k * 10_000 + 1_000;
            let mcu = k * 10_000 * 999_950 / 1_000_000;
            let mapped = m.map(host, mcu);
            worst = worst.max((host as i64 - mapped as i64).abs());
        }
        // Ten minutes: 30 ms of accumulated drift, followed to within the allowance's lag.
        assert!(worst <= 2, "worst {worst} us");
        assert_eq!(m.resets(), 0);
        let after = m.map(BASE_US + 700_000_000, 5_000);
        assert_eq!(m.resets(), 1);
        assert_eq!(after, BASE_US + 700_000_000);
    }

    #[test]
    fn one_very_late_report_does_not_move_the_clock() {
        let mut m = McuClockMap::new();
        for k in 0..100_u64 {
            m.map(BASE_US + k * 10_000 + 500, k * 10_000);
        }
        // A 250 ms stall of the service loop.
        assert_eq!(
            m.map(BASE_US + 1_000_000 + 250_000, 1_000_000),
            BASE_US + 1_000_000 + 500 + 2
        );
    }

    proptest! {
        #[test]
        fn mapped_stamps_increase_and_do_not_run_ahead_of_arrival(
            steps in prop::collection::vec((1_u64..20_000, 0_u64..50_000), 1..300),
        ) {
            let mut m = McuClockMap::new();
            let (mut mcu, mut rx, mut last) = (0_u64, BASE_US, 0_u64);
            for (dt, latency) in steps {
                mcu += dt;
                // Arrivals never go back in time.
                rx = rx.max(BASE_US + mcu + latency);
                let host = m.map(rx, mcu);
                prop_assert!(host > last, "{host} after {last}");
                prop_assert!(
                    host <= rx || host == last + 1,
                    "{host} later than its arrival {rx} (previous {last})"
                );
                last = host;
            }
        }
    }
}

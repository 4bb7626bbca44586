//! A seeded, lossy, rate-limited in-memory byte pipe: the radio (or UART) as tests and the
//! simulator see it. Deterministic for a seed; never reads a clock.
//!
//! The pipe cuts its input at frame delimiters (0x00) and treats each delimited run as one radio
//! packet: it is dropped with probability `loss`, or has one random bit flipped with probability
//! `corrupt` (which may hit the delimiter and merge two frames, as a real corrupted byte would).
//! With `burst_len` above 1 losses come in runs of that many frames (a fade), at the same
//! average loss.
//! Surviving bytes arrive after `latency_us` plus their serialisation time at `bytes_per_s`.

use std::collections::VecDeque;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Impairments of a [`LossyPipe`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipeConfig {
    /// Probability that a frame is lost.
    pub loss: f64,
    /// Probability that a (surviving) frame has one bit flipped.
    pub corrupt: f64,
    /// One-way latency, microseconds.
    pub latency_us: u64,
    /// Frames lost together in one loss event (1: independent losses).
    pub burst_len: u32,
    /// Byte rate of the line (0 = unlimited).
    pub bytes_per_s: u32,
}

impl PipeConfig {
    /// A clean line without latency.
    pub const CLEAN: Self = Self {
        loss: 0.0,
        corrupt: 0.0,
        latency_us: 0,
        burst_len: 1,
        bytes_per_s: 0,
    };

    /// The 57600-baud radio with the given loss and corruption and 20 ms modem latency.
    pub const fn radio_lossy(loss: f64, corrupt: f64) -> Self {
        Self {
            loss,
            corrupt,
            latency_us: 20_000,
            burst_len: 1,
            bytes_per_s: 5_760,
        }
    }

    /// The same with losses in runs of `burst_len` frames.
    #[must_use]
    pub const fn with_bursts(mut self, burst_len: u32) -> Self {
        self.burst_len = burst_len;
        self
    }
}

/// Counters of a [`LossyPipe`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PipeStats {
    /// Frames offered.
    pub frames: u64,
    /// Frames dropped.
    pub lost: u64,
    /// Frames corrupted.
    pub corrupted: u64,
}

/// One direction of a simulated serial link. See the module docs.
#[derive(Debug)]
pub struct LossyPipe {
    config: PipeConfig,
    rng: ChaCha8Rng,
    partial: Vec<u8>,
    in_transit: VecDeque<(u64, Vec<u8>)>,
    line_free_us: u64,
    stats: PipeStats,
    cut: bool,
    burst_left: u32,
}

impl LossyPipe {
    /// A pipe with its own seeded random stream.
    pub fn new(config: PipeConfig, seed: u64) -> Self {
        Self {
            config,
            rng: ChaCha8Rng::seed_from_u64(seed),
            partial: Vec::new(),
            in_transit: VecDeque::new(),
            line_free_us: 0,
            stats: PipeStats::default(),
            cut: false,
            burst_left: 0,
        }
    }

    /// Cuts (or restores) the line: while cut, everything pushed is lost (a vanished peer).
    pub fn set_cut(&mut self, cut: bool) {
        self.cut = cut;
    }

    /// Counters.
    pub fn stats(&self) -> PipeStats {
        self.stats
    }

    /// Bytes written into the pipe at `now_us`.
    pub fn push(&mut self, now_us: u64, bytes: &[u8]) {
        for &b in bytes {
            self.partial.push(b);
            if b == 0 {
                let frame = std::mem::take(&mut self.partial);
                self.offer(now_us, frame);
            }
        }
    }

    fn offer(&mut self, now_us: u64, mut frame: Vec<u8>) {
        self.stats.frames += 1;
        if self.cut || self.lose() {
            self.stats.lost += 1;
            return;
        }
        if self.rng.random_bool(self.config.corrupt.clamp(0.0, 1.0)) {
            self.stats.corrupted += 1;
            let i = self.rng.random_range(0..frame.len());
            let bit = self.rng.random_range(0..8);
            frame[i] ^= 1 << bit;
        }
        let start = self.line_free_us.max(now_us);
        let tx_us = if self.config.bytes_per_s == 0 {
            0
        } else {
            frame.len() as u64 * 1_000_000 / u64::from(self.config.bytes_per_s)
        };
        self.line_free_us = start + tx_us;
        self.in_transit
            .push_back((start + tx_us + self.config.latency_us, frame));
    }

    /// Whether the next frame is lost: a new loss event starts with the probability that keeps
    /// the average at `loss` (q = f / (L (1 - f) + f) for runs of L frames).
    fn lose(&mut self) -> bool {
        if self.burst_left > 0 {
            self.burst_left -= 1;
            return true;
        }
        let f = self.config.loss.clamp(0.0, 1.0);
        let l = f64::from(self.config.burst_len.max(1));
        let q = if f >= 1.0 {
            1.0
        } else {
            f / (l * (1.0 - f) + f)
        };
        if self.rng.random_bool(q.clamp(0.0, 1.0)) {
            self.burst_left = self.config.burst_len.max(1) - 1;
            return true;
        }
        false
    }

    /// Bytes that have arrived by `now_us`.
    pub fn pop(&mut self, now_us: u64) -> Vec<u8> {
        let mut out = Vec::new();
        while let Some((at, _)) = self.in_transit.front() {
            if *at > now_us {
                break;
            }
            if let Some((_, bytes)) = self.in_transit.pop_front() {
                out.extend(bytes);
            }
        }
        out
    }

    /// When the next bytes arrive, if any are in transit.
    pub fn next_arrival_us(&self) -> Option<u64> {
        self.in_transit.front().map(|(at, _)| *at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_impairments_and_rates_near_config() {
        let cfg = PipeConfig {
            loss: 0.2,
            corrupt: 0.2,
            latency_us: 0,
            burst_len: 1,
            bytes_per_s: 0,
        };
        let run = |seed| {
            let mut p = LossyPipe::new(cfg, seed);
            for i in 0..5_000u32 {
                p.push(u64::from(i), &[1, 2, 3, (i % 250 + 1) as u8, 0]);
            }
            (p.pop(u64::MAX), p.stats())
        };
        let (a, sa) = run(9);
        let (b, sb) = run(9);
        assert_eq!(a, b);
        assert_eq!(sa, sb);
        let loss = sa.lost as f64 / sa.frames as f64;
        assert!((loss - 0.2).abs() < 0.03, "loss {loss}");
        let corrupt = sa.corrupted as f64 / (sa.frames - sa.lost) as f64;
        assert!((corrupt - 0.2).abs() < 0.03, "corrupt {corrupt}");
        assert_ne!(run(10).0, a, "another seed, other losses");
    }

    #[test]
    fn latency_and_byte_rate_delay_arrival() {
        let mut p = LossyPipe::new(PipeConfig::radio_lossy(0.0, 0.0), 0);
        p.push(0, &[7; 575]);
        p.push(0, &[0]);
        // 576 bytes at 5760 B/s = 100 ms, plus 20 ms latency.
        assert!(p.pop(119_999).is_empty());
        assert_eq!(p.pop(120_000).len(), 576);
    }
}

/// Two connected [`crate::Port`]s through a pair of [`LossyPipe`]s: the radio between a
/// handheld and the onboard service when both run in one process (tests, `passangle-sim demo`),
/// on the monotonic clock ([`LossyPortPair::new`]) or on a simulated one
/// ([`LossyPortPair::on_clock`]). Cutting the line ([`LossyPortPair::set_cut`]) makes a peer
/// vanish.
#[derive(Debug, Clone)]
pub struct LossyPortPair {
    inner: std::sync::Arc<std::sync::Mutex<PairInner>>,
}

#[derive(Debug)]
struct PairInner {
    clock: PairClock,
    a_to_b: LossyPipe,
    b_to_a: LossyPipe,
}

/// The time a [`LossyPortPair`] moves bytes by.
#[derive(Debug)]
enum PairClock {
    /// Microseconds since this instant.
    Monotonic(std::time::Instant),
    /// A simulated clock in microseconds that its owner advances.
    Shared(std::sync::Arc<std::sync::atomic::AtomicU64>),
}

impl PairInner {
    fn now_us(&self) -> u64 {
        match &self.clock {
            PairClock::Monotonic(epoch) => {
                u64::try_from(epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
            }
            PairClock::Shared(t) => t.load(std::sync::atomic::Ordering::Acquire),
        }
    }
}

/// One end of a [`LossyPortPair`].
#[derive(Debug)]
pub struct LossyPort {
    inner: std::sync::Arc<std::sync::Mutex<PairInner>>,
    is_a: bool,
    pending: VecDeque<u8>,
}

impl LossyPortPair {
    /// A pair with the same impairments both ways (seeds `seed` and `seed + 1`) on the
    /// monotonic clock.
    pub fn new(config: PipeConfig, seed: u64) -> (Self, LossyPort, LossyPort) {
        Self::with_clock(
            config,
            seed,
            PairClock::Monotonic(std::time::Instant::now()),
        )
    }

    /// The same on a simulated clock: `now_us` holds the time in microseconds, and bytes
    /// arrive when it has advanced past their arrival time.
    pub fn on_clock(
        config: PipeConfig,
        seed: u64,
        now_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
    ) -> (Self, LossyPort, LossyPort) {
        Self::with_clock(config, seed, PairClock::Shared(now_us))
    }

    fn with_clock(config: PipeConfig, seed: u64, clock: PairClock) -> (Self, LossyPort, LossyPort) {
        let inner = std::sync::Arc::new(std::sync::Mutex::new(PairInner {
            clock,
            a_to_b: LossyPipe::new(config, seed),
            b_to_a: LossyPipe::new(config, seed.wrapping_add(1)),
        }));
        let end = |is_a| LossyPort {
            inner: std::sync::Arc::clone(&inner),
            is_a,
            pending: VecDeque::new(),
        };
        (
            Self {
                inner: std::sync::Arc::clone(&inner),
            },
            end(true),
            end(false),
        )
    }

    /// Cuts or restores both directions.
    pub fn set_cut(&self, cut: bool) {
        if let Ok(mut g) = self.inner.lock() {
            g.a_to_b.set_cut(cut);
            g.b_to_a.set_cut(cut);
        }
    }

    /// Counters of the a->b and b->a directions.
    pub fn stats(&self) -> (PipeStats, PipeStats) {
        self.inner
            .lock()
            .map_or((PipeStats::default(), PipeStats::default()), |g| {
                (g.a_to_b.stats(), g.b_to_a.stats())
            })
    }
}

impl std::io::Read for LossyPort {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.pending.is_empty() {
            let mut g = self
                .inner
                .lock()
                .map_err(|_| std::io::Error::other("lossy pipe poisoned"))?;
            let now = g.now_us();
            let pipe = if self.is_a {
                &mut g.b_to_a
            } else {
                &mut g.a_to_b
            };
            self.pending.extend(pipe.pop(now));
        }
        let n = buf.len().min(self.pending.len());
        for (dst, src) in buf.iter_mut().zip(self.pending.drain(..n)) {
            *dst = src;
        }
        Ok(n)
    }
}

impl std::io::Write for LossyPort {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let mut g = self
            .inner
            .lock()
            .map_err(|_| std::io::Error::other("lossy pipe poisoned"))?;
        let now = g.now_us();
        let pipe = if self.is_a {
            &mut g.a_to_b
        } else {
            &mut g.b_to_a
        };
        pipe.push(now, buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

//! The MCU link's byte pipe between the simulated onboard computer and the firmware's UART.
//!
//! [`ByteLink`] is one end of a full-duplex byte stream: write everything, read whatever has
//! arrived, never block. Two implementations:
//! - [`MemPipe`]: an in-memory pair, delivery immediate and deterministic (virtual-clock runs);
//! - [`PtyLink`]: a pseudo-terminal pair from `serialport` (`TTYPort::pair`, no unsafe code here),
//!   the same kind of device node a real UART adapter is, for real-time runs and for connecting an
//!   external program to the simulated firmware ([`PtyLink::slave_path`]).
//!
//! A pty delivers through the kernel's tty layer, asynchronously: a byte written now may be
//! readable a little later, so pty runs are real-time runs.

use std::collections::VecDeque;
use std::io::{Read as _, Write as _};
use std::sync::{Arc, Mutex, PoisonError};

/// One end of a byte stream.
pub trait ByteLink {
    /// Writes all of `bytes`.
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()>;
    /// Appends every byte that has arrived to `out`; never blocks.
    fn read_available(&mut self, out: &mut Vec<u8>) -> std::io::Result<()>;
}

type Queue = Arc<Mutex<VecDeque<u8>>>;

/// One end of an in-memory byte pipe.
#[derive(Debug)]
pub struct MemPipe {
    rx: Queue,
    tx: Queue,
}

impl MemPipe {
    /// Two connected ends.
    pub fn pair() -> (Self, Self) {
        let a: Queue = Arc::default();
        let b: Queue = Arc::default();
        (
            Self {
                rx: a.clone(),
                tx: b.clone(),
            },
            Self { rx: b, tx: a },
        )
    }
}

/// `Read + Write` over the pipe (what the onboard service takes for its serial ports): a read
/// takes what has arrived (possibly nothing), a write queues everything.
impl std::io::Read for MemPipe {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let mut rx = self.rx.lock().unwrap_or_else(PoisonError::into_inner);
        let n = out.len().min(rx.len());
        for (dst, src) in out.iter_mut().zip(rx.drain(..n)) {
            *dst = src;
        }
        Ok(n)
    }
}

impl std::io::Write for MemPipe {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        ByteLink::write_all(self, bytes)?;
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl ByteLink for MemPipe {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.tx
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .extend(bytes);
        Ok(())
    }

    fn read_available(&mut self, out: &mut Vec<u8>) -> std::io::Result<()> {
        out.extend(
            self.rx
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .drain(..),
        );
        Ok(())
    }
}

/// One end of a pseudo-terminal pair (raw mode, as `serialport` opens it).
pub struct PtyLink {
    port: serialport::TTYPort,
}

impl std::fmt::Debug for PtyLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use serialport::SerialPort as _;
        f.debug_struct("PtyLink")
            .field("name", &self.port.name())
            .finish()
    }
}

impl PtyLink {
    /// A connected pair: (master end, slave end). The slave has a device path
    /// ([`PtyLink::slave_path`]) that another program can open as its serial port.
    pub fn pair() -> Result<(Self, Self), serialport::Error> {
        use serialport::SerialPort as _;
        let (mut master, mut slave) = serialport::TTYPort::pair()?;
        for port in [&mut master, &mut slave] {
            port.set_timeout(std::time::Duration::ZERO)?;
        }
        Ok((Self { port: master }, Self { port: slave }))
    }

    /// The device path of this end (e.g. `/dev/pts/7`), if it has one.
    pub fn slave_path(&self) -> Option<String> {
        use serialport::SerialPort as _;
        self.port.name()
    }
}

impl ByteLink for PtyLink {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.port.write_all(bytes)?;
        self.port.flush()
    }

    fn read_available(&mut self, out: &mut Vec<u8>) -> std::io::Result<()> {
        use serialport::SerialPort as _;
        let mut buf = [0u8; 4096];
        loop {
            let waiting = self.port.bytes_to_read().map_err(std::io::Error::other)?;
            if waiting == 0 {
                return Ok(());
            }
            let want = buf.len().min(waiting as usize);
            match self.port.read(&mut buf[..want]) {
                Ok(0) => return Ok(()),
                Ok(n) => out.extend_from_slice(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mem_pipe_is_full_duplex() {
        let (mut a, mut b) = MemPipe::pair();
        ByteLink::write_all(&mut a, b"ping").unwrap();
        ByteLink::write_all(&mut b, b"pong").unwrap();
        let mut got = Vec::new();
        b.read_available(&mut got).unwrap();
        assert_eq!(got, b"ping");
        got.clear();
        a.read_available(&mut got).unwrap();
        assert_eq!(got, b"pong");
        got.clear();
        a.read_available(&mut got).unwrap();
        assert!(got.is_empty());
    }

    #[test]
    fn pty_pair_carries_binary_bytes_both_ways() {
        let (mut master, mut slave) = PtyLink::pair().expect("this machine can open a pty pair");
        assert!(slave.slave_path().is_some_and(|p| p.starts_with("/dev/")));
        // Raw mode: 0x00, 0x03 (^C), 0x0A/0x0D and 0x11/0x13 (XON/XOFF) must pass untouched.
        let bytes: Vec<u8> = (0..=255u8).collect();
        master.write_all(&bytes).unwrap();
        let mut got = Vec::new();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
        while got.len() < bytes.len() && std::time::Instant::now() < deadline {
            slave.read_available(&mut got).unwrap();
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert_eq!(got, bytes);
        slave.write_all(&[0, 1, 2]).unwrap();
        let mut back = Vec::new();
        while back.len() < 3 && std::time::Instant::now() < deadline {
            master.read_available(&mut back).unwrap();
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        assert_eq!(back, [0, 1, 2]);
    }
}

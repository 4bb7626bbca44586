//! The D435's depth stream over V4L2 (UVC, Z16 848x480 at 30 Hz by default).
//!
//! [`z16_frame`] turns one captured buffer into a [`DepthFrame`] (pure, always built, tested).
//! `spawn_v4l2_depth` opens the device, sets the Z16 format and frame rate, and captures with an
//! mmap stream on its own thread; it needs the `v4l2` cargo feature (the `v4l` crate, whose
//! bindings need libclang at build time: `apt-get install libclang-dev`, then
//! `cargo build --release -p onboard --features v4l2`). V4L2 reports neither intrinsics nor the depth
//! scale: both come from `[camera]` in the config.

/// One depth frame (Z16).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthFrame {
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Row-major depth in units of the configured depth scale, 0 = no return.
    pub depth: Vec<u16>,
}

/// Why a captured buffer is not a depth frame.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Z16Error {
    /// The buffer is shorter than `stride * height`.
    #[error(
        "Z16 buffer of {len} bytes is shorter than {needed} ({width}x{height}, stride {stride_bytes} B)"
    )]
    Short {
        /// Bytes received.
        len: usize,
        /// Bytes needed.
        needed: usize,
        /// Width, pixels.
        width: u16,
        /// Height, pixels.
        height: u16,
        /// Row stride, bytes.
        stride_bytes: u32,
    },
    /// The stride is smaller than two bytes per pixel.
    #[error("Z16 stride {stride_bytes} B is less than 2 x width {width}")]
    Stride {
        /// Row stride, bytes.
        stride_bytes: u32,
        /// Width, pixels.
        width: u16,
    },
}

/// One Z16 buffer (little-endian u16 per pixel, rows `stride_bytes` apart) as a row-major frame.
pub fn z16_frame(
    bytes: &[u8],
    width: u16,
    height: u16,
    stride_bytes: u32,
) -> Result<DepthFrame, Z16Error> {
    let row_bytes = usize::from(width) * 2;
    let stride = stride_bytes as usize;
    if stride < row_bytes {
        return Err(Z16Error::Stride {
            stride_bytes,
            width,
        });
    }
    let needed = stride * usize::from(height).saturating_sub(1) + row_bytes;
    if height > 0 && bytes.len() < needed {
        return Err(Z16Error::Short {
            len: bytes.len(),
            needed,
            width,
            height,
            stride_bytes,
        });
    }
    let mut depth = Vec::with_capacity(usize::from(width) * usize::from(height));
    for row in 0..usize::from(height) {
        let start = row * stride;
        depth.extend(
            bytes[start..start + row_bytes]
                .chunks_exact(2)
                .map(|p| u16::from_le_bytes([p[0], p[1]])),
        );
    }
    Ok(DepthFrame {
        width,
        height,
        depth,
    })
}

/// Opens the V4L2 depth node of `config` and captures on a thread until `shutdown`; frames arrive
/// on the returned channel (dropped, and counted in the log, when the service falls behind).
#[cfg(feature = "v4l2")]
pub fn spawn_v4l2_depth(
    config: &crate::config::CameraConfig,
    shutdown: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::io::Result<std::sync::mpsc::Receiver<DepthFrame>> {
    use std::sync::atomic::Ordering;
    use std::time::Duration;

    use v4l::buffer::Type;
    use v4l::io::traits::CaptureStream;
    use v4l::prelude::*;
    use v4l::video::Capture;

    let device = config.device.clone();
    let named = |what: &str, e: std::io::Error| {
        std::io::Error::new(e.kind(), format!("{}: {what}: {e}", device.display()))
    };
    let dev = Device::with_path(&device).map_err(|e| named("opening", e))?;
    let wanted = v4l::Format::new(
        u32::from(config.width),
        u32::from(config.height),
        v4l::FourCC::new(b"Z16 "),
    );
    let got = dev
        .set_format(&wanted)
        .map_err(|e| named("setting Z16", e))?;
    if got.fourcc != wanted.fourcc || got.width != wanted.width || got.height != wanted.height {
        return Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            format!(
                "{}: asked for Z16 {}x{}, the driver offers {} {}x{} (is this the depth node?)",
                device.display(),
                wanted.width,
                wanted.height,
                got.fourcc,
                got.width,
                got.height
            ),
        ));
    }
    dev.set_params(&v4l::video::capture::Parameters::with_fps(config.fps))
        .map_err(|e| named("setting the frame rate", e))?;
    let mut stream =
        MmapStream::with_buffers(&dev, Type::VideoCapture, 4).map_err(|e| named("mmap", e))?;
    stream.set_timeout(Duration::from_millis(200));
    let (tx, rx) = std::sync::mpsc::sync_channel(8);
    let (width, height, stride) = (config.width, config.height, got.stride);
    std::thread::Builder::new()
        .name("d435".into())
        .spawn(move || {
            let _keep_device_open = dev;
            let mut dropped = 0u64;
            while !shutdown.load(Ordering::Relaxed) {
                match stream.next() {
                    Ok((buf, _meta)) => match z16_frame(buf, width, height, stride) {
                        Ok(frame) => {
                            if tx.try_send(frame).is_err() {
                                dropped += 1;
                                if dropped.is_power_of_two() {
                                    tracing::warn!(
                                        dropped,
                                        "depth frames dropped: the service falls behind"
                                    );
                                }
                            }
                        }
                        Err(e) => tracing::warn!("{}: {e}", device.display()),
                    },
                    Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                    Err(e) => {
                        tracing::error!("{}: capture: {e}", device.display());
                        std::thread::sleep(Duration::from_millis(100));
                    }
                }
            }
        })?;
    Ok(rx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z16_rows_with_padding_decode_little_endian() {
        // 2x2 image, stride 6 bytes (2 padding bytes per row).
        let bytes = [
            0x01, 0x00, 0x34, 0x12, 0xEE, 0xEE, 0xFF, 0xFF, 0x00, 0x00, 0xEE, 0xEE,
        ];
        let f = z16_frame(&bytes, 2, 2, 6).unwrap();
        assert_eq!(f.depth, vec![1, 0x1234, 0xFFFF, 0]);
        assert_eq!((f.width, f.height), (2, 2));
    }

    #[test]
    fn short_buffers_and_bad_strides_are_named() {
        assert!(matches!(
            z16_frame(&[0; 5], 2, 2, 4),
            Err(Z16Error::Short { needed: 8, .. })
        ));
        assert!(matches!(
            z16_frame(&[0; 8], 2, 2, 3),
            Err(Z16Error::Stride { .. })
        ));
        // The last row needs no padding.
        assert!(z16_frame(&[0; 10], 2, 2, 6).is_ok());
    }

    #[cfg(feature = "v4l2")]
    #[test]
    fn a_missing_device_is_an_error_naming_it() {
        let config = crate::config::CameraConfig {
            device: "/dev/passangle-no-such-video".into(),
            ..crate::config::CameraConfig::default()
        };
        let shutdown = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let e = spawn_v4l2_depth(&config, shutdown).unwrap_err().to_string();
        assert!(e.contains("/dev/passangle-no-such-video: opening"), "{e}");
    }
}

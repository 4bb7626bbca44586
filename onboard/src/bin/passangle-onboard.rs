//! `passangle-onboard`: the robot's service (see `onboard::service` and docs/operator/run.md).
//!
//! ```text
//! passangle-onboard run --config /etc/passangle/onboard.toml
//! passangle-onboard check-config /etc/passangle/onboard.toml
//! passangle-onboard device-key --generate /etc/passangle/device.key
//! passangle-onboard device-key --public /etc/passangle/device.key
//! ```
//!
//! Exit codes follow sysexits: 64 usage, 65 bad config data, 66 missing input, 69 a device is
//! unavailable, 70 internal error, 73 a key file cannot be created (it exists, or no directory).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context;
use clap::{Parser, Subcommand};
use link::Port;
use onboard::config::{CameraSource, OnboardConfig};
use onboard::process::PipelineProcessor;
use onboard::service::{self, Io, Notifier};

/// passangle onboard service: drives the robot under a vehicle and measures its angles.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Log filter (tracing-subscriber EnvFilter syntax), e.g. `info`, `onboard=debug`.
    #[arg(long, default_value = "info", global = true)]
    log_level: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the service.
    Run {
        /// Configuration file.
        #[arg(long, default_value = "/etc/passangle/onboard.toml")]
        config: PathBuf,
    },
    /// Check a configuration file and print the effective values of the main keys.
    CheckConfig {
        /// Configuration file.
        file: PathBuf,
    },
    /// List the paired handhelds' keys (`radio.key-file`), or revoke one (takes effect when the
    /// service restarts).
    Keys {
        /// Configuration file (its `radio.key-file` is used).
        #[arg(long, default_value = "/etc/passangle/onboard.toml")]
        config: PathBuf,
        /// Key id to revoke (eight hex digits, as listed).
        #[arg(long)]
        revoke: Option<String>,
    },
    /// Make the robot's Ed25519 device key (`signing.key-file`), or print its public key: the
    /// key a lab gives `passangle verify` to check the robot's signed records.
    DeviceKey {
        /// Write a new key to FILE (mode 0600; refuses to overwrite) and print its public key.
        #[arg(
            long,
            value_name = "FILE",
            conflicts_with = "public",
            required_unless_present = "public"
        )]
        generate: Option<PathBuf>,
        /// Print the public key of the key in FILE.
        #[arg(long, value_name = "FILE")]
        public: Option<PathBuf>,
    },
}

/// sysexits(3) codes.
mod exit {
    pub const USAGE: u8 = 64;
    pub const DATAERR: u8 = 65;
    pub const NOINPUT: u8 = 66;
    pub const UNAVAILABLE: u8 = 69;
    pub const SOFTWARE: u8 = 70;
    pub const CANTCREAT: u8 = 73;
}

struct SdNotify;

impl Notifier for SdNotify {
    fn ready(&mut self) {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    }
    fn watchdog(&mut self) {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
    }
    fn status(&mut self, text: &str) {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Status(text)]);
    }
    fn stopping(&mut self) {
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Logs go to stderr without ANSI colours or timestamps when under systemd (journald adds them).
    let under_systemd = std::env::var_os("JOURNAL_STREAM").is_some();
    let filter = tracing_subscriber::EnvFilter::try_new(&cli.log_level)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(!under_systemd);
    if under_systemd {
        builder.without_time().init();
    } else {
        builder.init();
    }
    match cli.command {
        Command::CheckConfig { file } => check_config(&file),
        Command::Keys { config, revoke } => match keys(&config, revoke.as_deref()) {
            Ok(()) => ExitCode::SUCCESS,
            Err((code, e)) => {
                eprintln!("passangle-onboard keys: {e:#}");
                ExitCode::from(code)
            }
        },
        Command::DeviceKey { generate, public } => match device_key(generate, public) {
            Ok(()) => ExitCode::SUCCESS,
            Err((code, e)) => {
                eprintln!("passangle-onboard device-key: {e:#}");
                ExitCode::from(code)
            }
        },
        Command::Run { config } => match run(&config) {
            Ok(()) => ExitCode::SUCCESS,
            Err((code, e)) => {
                tracing::error!("{e:#}");
                ExitCode::from(code)
            }
        },
    }
}

/// `keys`: lists the paired keys, or revokes one.
fn keys(config_path: &Path, revoke: Option<&str>) -> Result<(), (u8, anyhow::Error)> {
    let config = OnboardConfig::load(config_path).map_err(|e| (exit::DATAERR, e.into()))?;
    let file = &config.radio.key_file;
    if let Some(id) = revoke {
        let id = u32::from_str_radix(id.trim(), 16).map_err(|e| {
            (
                exit::DATAERR,
                anyhow::anyhow!("--revoke {id:?}: expected eight hex digits ({e})"),
            )
        })?;
        let gone = link::keys::revoke(file, id).map_err(|e| (exit::DATAERR, e.into()))?;
        println!(
            "revoked key {:08x} {} from {}; restart the service for it to take effect",
            gone.id,
            gone.label,
            file.display()
        );
        return Ok(());
    }
    let entries = link::keys::read(file).map_err(|e| (exit::NOINPUT, e.into()))?;
    for e in entries {
        println!("{:08x} {}", e.id, e.label);
    }
    Ok(())
}

/// `device-key`: makes a device key from the OS's random source, or reads one; prints the
/// public key and its id.
fn device_key(
    generate: Option<PathBuf>,
    public: Option<PathBuf>,
) -> Result<(), (u8, anyhow::Error)> {
    let key = if let Some(file) = generate {
        let mut seed = [0u8; signing::SEED_LEN];
        getrandom::fill(&mut seed).map_err(|e| {
            (
                exit::SOFTWARE,
                anyhow::anyhow!("no random source for the key: {e}"),
            )
        })?;
        onboard::config::write_device_key(&file, &seed)
            .map_err(|e| (exit::CANTCREAT, anyhow::anyhow!("{e}")))?;
        let key = signing::DeviceKey::from_seed(&seed);
        eprintln!(
            "wrote a new device key to {} (mode 0600); set signing.key-file to it and give the \
             public key below to whoever checks the robot's records",
            file.display()
        );
        key
    } else if let Some(file) = public {
        onboard::config::read_device_key(&file).map_err(|e| {
            let code = if matches!(e, onboard::config::ConfigError::Io { .. }) {
                exit::NOINPUT
            } else {
                exit::DATAERR
            };
            (code, anyhow::anyhow!("{e}"))
        })?
    } else {
        return Err((
            exit::USAGE,
            anyhow::anyhow!("give --generate FILE or --public FILE"),
        ));
    };
    let public = key.public();
    println!("{public} key id {}", public.id());
    Ok(())
}

fn check_config(file: &Path) -> ExitCode {
    // Every problem is printed (the values' and the key file's), not just the first;
    // the exit code is non-zero if there is any.
    let (config, problems) = OnboardConfig::check_file(file);
    for e in &problems {
        eprintln!("error: {e}");
    }
    let c = match config {
        Some(c) if problems.is_empty() => c,
        _ => {
            eprintln!("{}: {} problem(s)", file.display(), problems.len());
            let missing = matches!(
                problems.as_slice(),
                [onboard::config::ConfigError::Io { .. }]
            );
            return ExitCode::from(if missing {
                exit::NOINPUT
            } else {
                exit::DATAERR
            });
        }
    };
    println!("{}: ok", file.display());
    println!(
        "  radio       {} at {} baud, keys {}",
        c.radio.port,
        c.radio.baud,
        c.radio.key_file.display()
    );
    println!(
        "  mcu         {} at {} baud, heartbeat {} ms",
        c.mcu.port, c.mcu.baud, c.mcu.heartbeat_period_ms
    );
    println!(
        "  lidar       {} (position {:?})",
        c.lidar.data_addr, c.lidar.position_addr
    );
    println!(
        "  camera      {:?} {}",
        c.camera.source,
        c.camera.device.display()
    );
    println!("  recordings  {}", c.recording.root.display());
    match c.device_key() {
        Ok(Some(key)) => println!(
            "  signing     key {} ({}), public key {}",
            key.public().id(),
            c.signing
                .key_file
                .as_deref()
                .unwrap_or(Path::new(""))
                .display(),
            key.public()
        ),
        _ => println!("  signing     off: signing.key-file is not set, records are not signed"),
    }
    println!(
        "  run         max {} m/s, {} m",
        c.run.max_speed_mps, c.run.max_distance_m
    );
    ExitCode::SUCCESS
}

fn open_port(path: &str, baud: u32) -> anyhow::Result<Box<dyn Port>> {
    let port = serialport::new(path, baud)
        .timeout(Duration::from_millis(1))
        .open_native()
        .with_context(|| format!("opening serial port {path} at {baud} baud"))?;
    Ok(Box::new(port))
}

fn run(config_path: &Path) -> Result<(), (u8, anyhow::Error)> {
    let text = std::fs::read_to_string(config_path)
        .with_context(|| format!("reading {}", config_path.display()))
        .map_err(|e| (exit::NOINPUT, e))?;
    let config = OnboardConfig::parse(&text, config_path).map_err(|e| (exit::DATAERR, e.into()))?;
    // The pairing keys and the device key are checked as `check-config` checks them (owner,
    // mode, contents) before anything opens: a key file others can read is a key others may have
    // copied.
    if let Some(first) = config.file_problems().into_iter().next() {
        return Err((exit::DATAERR, first.into()));
    }
    let shutdown = Arc::new(AtomicBool::new(false));
    // Before any other thread starts, so that every thread inherits the blocked signals.
    install_signals(Arc::clone(&shutdown)).map_err(|e| (exit::SOFTWARE, e))?;
    let unavailable = |e: anyhow::Error| (exit::UNAVAILABLE, e);
    let radio = open_port(&config.radio.port, config.radio.baud).map_err(unavailable)?;
    let mcu = open_port(&config.mcu.port, config.mcu.baud).map_err(unavailable)?;
    let (lidar, _) = service::spawn_lidar_reader(&config.lidar, Arc::clone(&shutdown))
        .context("opening the lidar socket")
        .map_err(unavailable)?;
    let depth = match config.camera.source {
        CameraSource::None => None,
        CameraSource::V4l2 => Some(open_v4l2(&config, Arc::clone(&shutdown)).map_err(unavailable)?),
        CameraSource::Simulated => {
            return Err((
                exit::DATAERR,
                anyhow::anyhow!(
                    "{}: camera.source = \"simulated\" only works inside passangle-sim",
                    config_path.display()
                ),
            ));
        }
    };
    let processor = Arc::new(PipelineProcessor {
        config: config.processing.clone(),
    });
    let io = Io {
        radio,
        mcu,
        lidar,
        depth,
        crash: None,
    };
    service::run(
        config,
        text,
        io,
        processor,
        &shutdown,
        &mut SdNotify,
        Arc::new(Mutex::new(service::ServiceStats::default())),
    )
    .map_err(|e| (exit::SOFTWARE, e.into()))
}

/// SIGTERM and SIGINT are blocked in every thread and awaited by one thread that sets `flag`:
/// no async-signal handler, no unsafe code.
fn install_signals(flag: Arc<AtomicBool>) -> anyhow::Result<()> {
    use nix::sys::signal::{SigSet, Signal};
    let mut set = SigSet::empty();
    set.add(Signal::SIGTERM);
    set.add(Signal::SIGINT);
    set.thread_block().context("blocking SIGTERM/SIGINT")?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Ok(sig) = set.wait() {
                tracing::info!("{sig}: shutting down (the robot stops first)");
                flag.store(true, Ordering::Relaxed);
            }
        })
        .context("starting the signal thread")?;
    Ok(())
}

/// The D435's depth node through V4L2 (`onboard::camera`), in builds with the `v4l2` feature.
#[cfg(feature = "v4l2")]
fn open_v4l2(
    config: &OnboardConfig,
    shutdown: Arc<AtomicBool>,
) -> anyhow::Result<std::sync::mpsc::Receiver<service::DepthFrame>> {
    onboard::camera::spawn_v4l2_depth(&config.camera, shutdown).with_context(|| {
        format!(
            "camera.source = \"v4l2\" ({})",
            config.camera.device.display()
        )
    })
}

/// Without the `v4l2` feature there is no V4L2 capture: say how to get it.
#[cfg(not(feature = "v4l2"))]
fn open_v4l2(
    config: &OnboardConfig,
    _shutdown: Arc<AtomicBool>,
) -> anyhow::Result<std::sync::mpsc::Receiver<service::DepthFrame>> {
    anyhow::bail!(
        "camera.source = \"v4l2\" ({}): this passangle-onboard was built without the `v4l2` \
         feature (rebuild with `cargo build --release -p onboard --features v4l2`, which needs \
         libclang-dev), or set camera.source = \"none\" to run on lidar and wheel odometry",
        config.camera.device.display()
    )
}

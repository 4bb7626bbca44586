//! The operator's commands over the radio link: `pair`, `measure`, `status`, `abort`, `fetch`.
//! The link itself is `link::client` (shared with the simulator's demo).

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use link::Port;
use link::client::{Client, Measured, Observer};
use protocol::bounded::Text;
use protocol::common::LogLine;
use protocol::radio::{Phase, Progress, StartMeasurement, Zone};

fn default_key_file() -> PathBuf {
    std::env::var_os("HOME").map_or_else(
        || PathBuf::from("passangle.key"),
        |h| PathBuf::from(h).join(".config/passangle/pairing.key"),
    )
}

/// The radio port and pairing key every radio command needs.
#[derive(Args, Debug)]
pub struct LinkArgs {
    /// Serial device of the radio modem.
    #[arg(long, default_value = "/dev/ttyUSB0")]
    pub port: String,
    /// Baud rate of the radio modem.
    #[arg(long, default_value_t = 57_600)]
    pub baud: u32,
    /// Pairing key file (written by `passangle pair`).
    #[arg(long, default_value_os_t = default_key_file())]
    pub key_file: PathBuf,
    /// Seconds to wait for the robot to answer.
    #[arg(long, default_value_t = 10.0)]
    pub timeout_s: f64,
}

/// `passangle pair`.
#[derive(Args, Debug)]
pub struct PairArgs {
    /// Where to write the new key (mode 0600); its line goes into the robot's `radio.key-file`.
    #[arg(long, default_value_os_t = default_key_file())]
    pub key_file: PathBuf,
    /// Also add the key to this robot key list (the robot's `radio.key-file`, one key per line).
    #[arg(long)]
    pub robot_keys: Option<PathBuf>,
    /// Label stored with the key in the robot's list (e.g. the handheld's name).
    #[arg(long, default_value = "")]
    pub label: String,
}

/// Zone convention.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ZoneArg {
    /// Ahead of the tyre (CFR / SAE J1100).
    Tyre,
    /// Ahead of the axle (EU).
    Axle,
}

/// `passangle measure`.
#[derive(Args, Debug)]
pub struct MeasureArgs {
    #[command(flatten)]
    link: LinkArgs,
    /// Drive speed under the vehicle, m/s.
    #[arg(long, default_value_t = 0.2)]
    speed: f32,
    /// Distance to drive, m (vehicle length plus about a metre each side).
    #[arg(long, default_value_t = 7.0)]
    distance: f32,
    /// Vehicle identifier saved with the result (plate, VIN, test number; up to 32 bytes).
    #[arg(long, default_value = "")]
    vehicle_id: String,
    /// Zone convention for approach and departure.
    #[arg(long, value_enum, default_value_t = ZoneArg::Tyre)]
    zone: ZoneArg,
    /// Lab, customer and vehicle details (TOML, at most 4096 bytes; see
    /// docs/operator/lab.example.toml), sent to the robot for the run's record and the lab
    /// report it writes and signs.
    #[arg(long, value_name = "FILE")]
    lab: Option<PathBuf>,
    /// Directory for the result JSON, the preview PLY and the side-view SVG.
    #[arg(long, default_value = ".")]
    out: PathBuf,
    /// Longest the whole run may take, s.
    #[arg(long, default_value_t = 300.0)]
    run_timeout_s: f64,
}

/// `passangle fetch`.
#[derive(Args, Debug)]
pub struct FetchArgs {
    #[command(flatten)]
    link: LinkArgs,
    /// The run number.
    run: u32,
    /// Directory for the files.
    #[arg(long, default_value = ".")]
    out: PathBuf,
}

/// `passangle abort`.
#[derive(Args, Debug)]
pub struct AbortArgs {
    #[command(flatten)]
    link: LinkArgs,
    /// Run to abort (0: whatever runs).
    #[arg(long, default_value_t = 0)]
    run: u32,
}

/// `passangle status`.
#[derive(Args, Debug)]
pub struct StatusArgs {
    #[command(flatten)]
    link: LinkArgs,
}

/// Creates a new pairing key.
pub fn pair(args: &PairArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    if let Some(dir) = args.key_file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut key = [0u8; protocol::auth::KEY_LEN];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut key))
        .context("reading /dev/urandom")?;
    let key = protocol::auth::Key(key);
    link::keys::write_key(&args.key_file, &key)?;
    let id = protocol::auth::key_id(&key);
    writeln!(
        out,
        "wrote a new pairing key {id:08x} to {} (mode 0600).",
        args.key_file.display()
    )?;
    match &args.robot_keys {
        Some(robot) => {
            link::keys::add(robot, &key, &args.label)?;
            writeln!(
                out,
                "added key {id:08x} to the robot's key list {}; restart the service to use it.",
                robot.display()
            )?;
        }
        None => writeln!(
            out,
            "add its line to the robot's radio.key-file (default /etc/passangle/pairing.key, one key per line, mode 0600), e.g. with `passangle pair --robot-keys FILE` where that file is reachable, then restart the service."
        )?,
    }
    Ok(())
}

fn open(link: &LinkArgs) -> anyhow::Result<Client> {
    let key = link::keys::read(&link.key_file)?.swap_remove(0).key;
    let port: Box<dyn Port> = Box::new(
        serialport::new(&link.port, link.baud)
            .timeout(Duration::from_millis(2))
            .open_native()
            .with_context(|| {
                format!("opening the radio port {} at {} baud", link.port, link.baud)
            })?,
    );
    Ok(Client::new(port, key)?)
}

fn timeout(s: f64) -> Duration {
    Duration::from_secs_f64(s.clamp(0.1, 86_400.0))
}

/// The robot's progress on stderr while `measure` or `fetch` waits: a live bar on a terminal
/// ([`Live`]), plain lines otherwise ([`Lines`]).
enum Display {
    Live(Live),
    Lines(Lines<std::io::Stderr>),
}

impl Display {
    fn on_stderr() -> Self {
        if std::io::stderr().is_terminal() {
            Self::Live(Live::new())
        } else {
            Self::Lines(Lines::new(std::io::stderr()))
        }
    }

    fn observer(&mut self) -> &mut dyn Observer {
        match self {
            Self::Live(live) => live,
            Self::Lines(lines) => lines,
        }
    }

    /// Leaves the bar's last state on its own line, so what follows starts on a fresh one.
    fn finish(&self) {
        if let Self::Live(live) = self {
            live.bar.finish();
        }
    }
}

/// One bar that indicatif redraws in place, cut to the terminal's width so that it never wraps;
/// the robot's log lines are printed above it.
struct Live {
    bar: ProgressBar,
}

impl Live {
    fn new() -> Self {
        let style = ProgressStyle::with_template("{prefix} [{bar:20}] {percent:>3}%  {wide_msg}")
            .map_or_else(
                |_| ProgressStyle::default_bar(),
                |s| s.progress_chars("#>-"),
            );
        let bar = ProgressBar::new(100).with_style(style);
        bar.set_prefix("waiting for the robot");
        Self { bar }
    }
}

impl Observer for Live {
    fn progress(&mut self, p: &Progress) {
        self.bar
            .set_prefix(format!("run {} {:<10}", p.run_id, p.phase.name()));
        self.bar.set_length(100);
        self.bar.set_position(u64::from(p.percent.min(100)));
        self.bar.set_message(format!(
            "{:.2} m  {} lidar frames",
            p.travelled_m, p.lidar_frames
        ));
    }
    fn log(&mut self, l: &LogLine) {
        self.bar.println(log_text(l));
    }
    fn preview(&mut self, received: usize, total: usize) {
        self.bar.set_prefix("preview");
        self.bar.set_length(total.max(1) as u64);
        self.bar
            .set_position(if total == 0 { 1 } else { received as u64 });
        self.bar.set_message(format!("{received}/{total} chunks"));
    }
}

/// Plain lines for a log file or a pipe: a line when the run enters a phase and at each quarter
/// of it, and for the preview at its start, each quarter and its end; the robot's 2 Hz updates in
/// between are not printed.
struct Lines<W> {
    out: W,
    /// Run, phase and quarter (0..=4) of the last progress line printed.
    progress: Option<(u32, Phase, u8)>,
    /// Chunk total and quarter of the last preview line printed.
    preview: Option<(usize, usize)>,
}

impl<W: Write> Lines<W> {
    fn new(out: W) -> Self {
        Self {
            out,
            progress: None,
            preview: None,
        }
    }

    fn line(&mut self, text: &str) {
        let _ = writeln!(self.out, "{text}");
        let _ = self.out.flush();
    }
}

fn bar(percent: u8) -> String {
    let filled = usize::from(percent.min(100)) / 5;
    format!("[{}{}]", "#".repeat(filled), "-".repeat(20 - filled))
}

fn log_text(l: &LogLine) -> String {
    format!("robot {}: {}", l.level.name(), l.text.as_str())
}

impl<W: Write> Observer for Lines<W> {
    fn progress(&mut self, p: &Progress) {
        let at = Some((p.run_id, p.phase, p.percent.min(100) / 25));
        if at == self.progress {
            return;
        }
        self.progress = at;
        self.line(&format!(
            "run {} {:<10} {} {:3}%  {:.2} m  {} lidar frames",
            p.run_id,
            p.phase.name(),
            bar(p.percent),
            p.percent,
            p.travelled_m,
            p.lidar_frames
        ));
    }
    fn log(&mut self, l: &LogLine) {
        self.line(&log_text(l));
    }
    fn preview(&mut self, received: usize, total: usize) {
        let pct = (received * 100).checked_div(total).unwrap_or(100).min(100);
        let at = Some((total, pct / 25));
        if at == self.preview {
            return;
        }
        self.preview = at;
        self.line(&format!(
            "preview {} {received}/{total} chunks",
            bar(pct as u8)
        ));
    }
}

fn deg(rad: f32) -> String {
    if rad.is_finite() {
        format!("{:.1}", rad.to_degrees())
    } else {
        "n/a".into()
    }
}

/// Prints the result table.
pub fn print_result(m: &Measured, out: &mut dyn Write) -> std::io::Result<()> {
    let r = &m.result;
    writeln!(out, "run {}  vehicle {:?}", r.run_id, r.vehicle_id.as_str())?;
    writeln!(
        out,
        "  {:<18} {:>8} {:>9} {:>9}",
        "angle", "degrees", "U (k=2)", "support"
    )?;
    let rows = [
        (
            "approach",
            r.approach_rad,
            r.approach_u_rad,
            r.approach_support,
            r.absent[0],
        ),
        (
            "departure",
            r.departure_rad,
            r.departure_u_rad,
            r.departure_support,
            r.absent[1],
        ),
        (
            "ramp breakover",
            r.breakover_rad,
            r.breakover_u_rad,
            r.breakover_support,
            r.absent[2],
        ),
    ];
    for (name, rad, u_rad, support, absent) in rows {
        match absent.reason() {
            Some(why) => writeln!(out, "  {name:<18} not measured: {why}")?,
            None => writeln!(
                out,
                "  {name:<18} {:>8} {:>9} {support:>9}",
                deg(rad),
                deg(u_rad)
            )?,
        }
    }
    match r.absent[3].reason() {
        Some(why) => writeln!(out, "  ground clearance not measured: {why}")?,
        None => writeln!(
            out,
            "  ground clearance {:.3} m (U {:.3} m)",
            r.ground_clearance_m, r.ground_clearance_u_m
        )?,
    }
    writeln!(
        out,
        "  wheelbase {:.3} m, track {:.3} m",
        r.wheelbase_m, r.track_m
    )?;
    writeln!(
        out,
        "  tyre fit rms {:.1} mm, {} cloud points on the robot, warnings: {}",
        r.tyre_fit_rms_m * 1e3,
        r.cloud_points,
        r.warnings
    )?;
    if let Some(t) = m.stop_to_result {
        writeln!(
            out,
            "  robot at rest -> result here: {:.2} s",
            t.as_secs_f64()
        )?;
    }
    Ok(())
}

fn save_and_print(m: &Measured, dir: &Path, out: &mut dyn Write) -> anyhow::Result<()> {
    print_result(m, out)?;
    let files =
        link::client::save(dir, m).with_context(|| format!("saving into {}", dir.display()))?;
    writeln!(
        out,
        "saved {}, {}, {}",
        files.json.display(),
        files.ply.display(),
        files.svg.display()
    )?;
    if let Some(result) = files.result_json() {
        writeln!(
            out,
            "the robot's record, byte-exact: {} (check it: passangle verify {})",
            files
                .records
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            result.display()
        )?;
    }
    for why in &files.missing {
        writeln!(out, "not saved: {why}")?;
    }
    // Saved either way; the command fails when a quantity was not measured, as `angles` and
    // `replay` do, so scripts see a non-zero exit.
    let missing: Vec<String> = ["approach", "departure", "breakover", "ground clearance"]
        .iter()
        .zip(m.result.absent)
        .filter_map(|(name, a)| a.reason().map(|why| format!("{name} ({why})")))
        .collect();
    if !missing.is_empty() {
        anyhow::bail!(
            "run {}: not measured: {}",
            m.result.run_id,
            missing.join("; ")
        );
    }
    Ok(())
}

/// `passangle measure`.
pub fn measure(args: &MeasureArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let vehicle_id = Text::new(&args.vehicle_id)
        .with_context(|| format!("--vehicle-id {:?} is longer than 32 bytes", args.vehicle_id))?;
    let lab_bytes = match &args.lab {
        Some(p) => Some(read_lab(p)?),
        None => None,
    };
    let mut client = open(&args.link)?;
    client
        .connect(timeout(args.link.timeout_s))
        .context("connecting to the robot")?;
    let lab = match &lab_bytes {
        Some(bytes) => client
            .send_lab(bytes, timeout(args.link.timeout_s))
            .context("sending the lab file")?,
        None => protocol::radio::LabRef::NONE,
    };
    let params = StartMeasurement {
        vehicle_id,
        speed_mps: args.speed,
        distance_m: args.distance,
        zone: match args.zone {
            ZoneArg::Tyre => Zone::Tyre,
            ZoneArg::Axle => Zone::Axle,
        },
        lab,
    };
    let mut display = Display::on_stderr();
    let m = client.measure(&params, timeout(args.run_timeout_s), display.observer());
    display.finish();
    save_and_print(&m?, &args.out, out)
}

/// The lab file for `measure --lab`, checked here as the robot will check it, so a typo is
/// named before anything moves.
fn read_lab(path: &Path) -> anyhow::Result<Vec<u8>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let max = usize::from(protocol::radio::MAX_LAB_LEN);
    if bytes.len() > max {
        anyhow::bail!(
            "{}: {} bytes; the radio carries a lab file of at most {max}",
            path.display(),
            bytes.len()
        );
    }
    onboard::report::LabFile::parse_bytes(&bytes)
        .with_context(|| format!("{}: lab file", path.display()))?;
    Ok(bytes)
}

/// `passangle fetch`.
pub fn fetch(args: &FetchArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut client = open(&args.link)?;
    let mut display = Display::on_stderr();
    let m = client.fetch(
        args.run,
        timeout(args.link.timeout_s.max(120.0)),
        display.observer(),
    );
    display.finish();
    save_and_print(&m?, &args.out, out)
}

/// `passangle abort`.
pub fn abort(args: &AbortArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut client = open(&args.link)?;
    client.abort(args.run, timeout(args.link.timeout_s))?;
    writeln!(out, "abort acknowledged by the robot (it stops first)")?;
    Ok(())
}

/// `passangle status`.
pub fn status(args: &StatusArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut client = open(&args.link)?;
    let s = client.status(timeout(args.link.timeout_s))?;
    let ok = |b: bool| if b { "ok" } else { "NOT OK" };
    writeln!(out, "phase {} (run {})", s.phase, s.run_id)?;
    writeln!(
        out,
        "firmware {}, lidar {}, camera {}",
        ok(s.firmware_ok),
        ok(s.lidar_ok),
        ok(s.camera_ok)
    )?;
    writeln!(out, "interlocks: {}", s.interlocks)?;
    if s.battery_mv == 0 {
        writeln!(out, "battery: not measured")?;
    } else {
        writeln!(
            out,
            "battery: {:.2} V{}",
            f64::from(s.battery_mv) / 1e3,
            if s.interlocks
                .contains(protocol::mcu::Interlocks::BATTERY_LOW)
            {
                " (LOW: charge or swap the pack)"
            } else {
                ""
            }
        )?;
    }
    writeln!(
        out,
        "results waiting for this handheld: {}",
        s.pending_results
    )?;
    writeln!(out, "free space for recordings: {} MiB", s.disk_free_mib)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::common::LogLevel;

    fn progress(phase: Phase, percent: u8) -> Progress {
        Progress {
            run_id: 7,
            phase,
            percent,
            travelled_m: f32::from(percent) / 20.0,
            lidar_frames: u32::from(percent) * 10,
        }
    }

    /// Off a terminal the 2 Hz updates become a line per phase and quarter, the preview's many
    /// calls a line per quarter, and nothing rewrites a line.
    #[test]
    fn plain_lines_only_when_something_changed() {
        let mut lines = Lines::new(Vec::new());
        for (phase, percent) in [
            (Phase::Checks, 0),
            (Phase::Checks, 0),
            (Phase::Checks, 100),
            (Phase::Driving, 0),
            (Phase::Driving, 3),
            (Phase::Driving, 12),
            (Phase::Driving, 26),
            (Phase::Driving, 30),
            (Phase::Driving, 49),
            (Phase::Driving, 100),
            (Phase::Driving, 100),
            (Phase::Processing, 0),
        ] {
            lines.progress(&progress(phase, percent));
        }
        lines.log(&LogLine {
            level: LogLevel::Warn,
            text: Text::truncated("tyre fit poor"),
        });
        for received in [0, 0, 1, 1, 2, 3, 3, 4, 4] {
            lines.preview(received, 4);
        }
        let text = String::from_utf8(lines.out).unwrap();
        assert_eq!(
            text.lines().collect::<Vec<_>>(),
            [
                "run 7 Checks     [--------------------]   0%  0.00 m  0 lidar frames",
                "run 7 Checks     [####################] 100%  5.00 m  1000 lidar frames",
                "run 7 Driving    [--------------------]   0%  0.00 m  0 lidar frames",
                "run 7 Driving    [#####---------------]  26%  1.30 m  260 lidar frames",
                "run 7 Driving    [####################] 100%  5.00 m  1000 lidar frames",
                "run 7 Processing [--------------------]   0%  0.00 m  0 lidar frames",
                "robot Warn: tyre fit poor",
                "preview [--------------------] 0/4 chunks",
                "preview [#####---------------] 1/4 chunks",
                "preview [##########----------] 2/4 chunks",
                "preview [###############-----] 3/4 chunks",
                "preview [####################] 4/4 chunks",
            ]
        );
        assert!(!text.contains(['\r', '\x1b']), "{text:?}");
    }
}

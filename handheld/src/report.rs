//! `passangle report RUN_DIR [--lab lab.toml]`: the lab report of a recorded run, written on this
//! machine from a copy of the run directory (`onboard::report` holds the report; the robot
//! writes the same report, signed, when a run closes).

use std::path::PathBuf;

use anyhow::Context;
use onboard::report::{self, Inputs, LabFile, Writer};

use crate::verify;

/// Arguments of `passangle report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// The run directory (meta.json, result.json, cloud.ply, config.toml, ...).
    pub run_dir: PathBuf,
    /// Lab, customer and vehicle details (TOML; see docs/operator/lab.example.toml). Default:
    /// the run's own lab.toml, the one sent with `passangle measure --lab`, if any.
    #[arg(long, value_name = "FILE")]
    pub lab: Option<PathBuf>,
    /// Where to write the report (default RUN_DIR/report-handheld.html: the robot's own,
    /// signed report.html is never overwritten).
    #[arg(long, value_name = "FILE.html")]
    pub out: Option<PathBuf>,
    /// A trusted robot public key (64 hex digits): the report states whether each signed file
    /// verifies against it. May be repeated. Without a key the signatures are not checked.
    #[arg(long = "public-key", value_name = "KEY")]
    pub public_keys: Vec<String>,
    /// A file of trusted robot public keys (as for `passangle verify --keys`).
    #[arg(long, value_name = "FILE")]
    pub keys: Option<PathBuf>,
}

/// Run the command.
pub fn run(args: &ReportArgs, out: &mut impl std::io::Write) -> anyhow::Result<()> {
    let path = args
        .out
        .clone()
        .unwrap_or_else(|| args.run_dir.join("report-handheld.html"));
    let lab = match &args.lab {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            let lab =
                LabFile::parse(&text).with_context(|| format!("{}: lab file", p.display()))?;
            Some((lab, p.display().to_string()))
        }
        None => None,
    };
    let trusted = verify::given_keys(&args.public_keys, args.keys.as_deref())?;
    let report = report::gather(&Inputs {
        run_dir: &args.run_dir,
        lab,
        out: &path,
        trusted: &trusted,
        written_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        writer: Writer::Handheld,
    })?;
    let html = report::render(&report);
    std::fs::write(&path, html).with_context(|| format!("writing {}", path.display()))?;
    writeln!(out, "wrote {} (report {})", path.display(), report.id)?;
    Ok(())
}

//! Embeds the git commit onboard is built from (`PASSANGLE_GIT_HASH`), for the lab report's
//! provenance (`onboard::report`). Outside a git checkout, or without git, it is "unknown": the build never
//! fails for it. `PASSANGLE_GIT_HASH` set in the environment wins (a packager's build from a
//! tarball).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_owned();
    (!s.is_empty()).then_some(s)
}

fn main() {
    println!("cargo:rerun-if-env-changed=PASSANGLE_GIT_HASH");
    let hash = std::env::var("PASSANGLE_GIT_HASH")
        .ok()
        .filter(|h| !h.is_empty())
        .or_else(|| git(&["rev-parse", "HEAD"]))
        .unwrap_or_else(|| "unknown".to_owned());
    // Rebuild when the checked-out commit moves: HEAD, and the branch it points at.
    for path in ["HEAD", "packed-refs"] {
        if let Some(p) = git(&["rev-parse", "--git-path", path]) {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    if let Some(p) = git(&["symbolic-ref", "-q", "HEAD"])
        .and_then(|branch| git(&["rev-parse", "--git-path", &branch]))
    {
        println!("cargo:rerun-if-changed={p}");
    }
    println!("cargo:rustc-env=PASSANGLE_GIT_HASH={hash}");
}

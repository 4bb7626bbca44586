//! The lab report in a real browser: headless Chromium renders it to a PNG, which must be a
//! page-sized picture with content. Required unless `PASSANGLE_SKIP_BROWSER=1` (scripts/test.sh
//! installs Chromium). Shared by the handheld's report test and the lockstep demo's test.
#![allow(clippy::unwrap_used, dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Renders the report in headless Chromium and checks the screenshot is a real picture.
pub fn screenshot(html: &Path, root: &Path) {
    let Some(browser) = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| {
            Command::new(b)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
    else {
        assert!(
            std::env::var_os("PASSANGLE_SKIP_BROWSER").is_some_and(|v| v == "1"),
            "no chromium on PATH: install it (apt-get install chromium; scripts/test.sh does) or \
             set PASSANGLE_SKIP_BROWSER=1 to skip the browser check"
        );
        eprintln!("SKIPPED: no chromium on PATH (PASSANGLE_SKIP_BROWSER=1)");
        return;
    };
    let png = std::env::var_os("PASSANGLE_REPORT_PNG")
        .map_or_else(|| root.join("report.png"), PathBuf::from);
    let out = Command::new(browser)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            &format!(
                "--user-data-dir={}",
                root.join("chromium-profile").display()
            ),
            &format!("--screenshot={}", png.display()),
            "--window-size=1200,3000",
            &format!("file://{}", html.display()),
        ])
        .output()
        .unwrap();
    let bytes = std::fs::read(&png).unwrap_or_else(|e| {
        panic!(
            "{browser} wrote no screenshot ({e}): {}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
    let width = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert!(width >= 1000 && height >= 2000, "{width} x {height}");
    // A blank page of this size compresses to a few KB; text, tables and clouds do not.
    assert!(
        bytes.len() > 100_000,
        "screenshot only {} bytes: blank?",
        bytes.len()
    );
}

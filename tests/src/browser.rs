//! The browser tests' tools: Node.js, Debian's Chromium and the scripts' packages
//! (`tests/browser/`, playwright-core), found or said missing.

use std::path::{Path, PathBuf};
use std::process::Command;

/// `tests/browser/` of this workspace.
pub fn scripts() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("browser")
}

/// Chromium's path when Node.js, Chromium (`/usr/bin/chromium`, or `BSPVT_CHROMIUM`) and
/// `tests/browser/node_modules` are all there; otherwise why the browser test cannot run
/// (`.ci/run` installs them).
pub fn tools() -> Result<PathBuf, String> {
    let node = Command::new("node").arg("--version").output();
    if !node.is_ok_and(|o| o.status.success()) {
        return Err("no `node` on PATH".into());
    }
    let chromium = std::env::var_os("BSPVT_CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    if !chromium.exists() {
        return Err(format!(
            "no Chromium at {} (apt-get install chromium, or set BSPVT_CHROMIUM)",
            chromium.display()
        ));
    }
    if !scripts().join("node_modules/playwright-core").exists() {
        return Err("tests/browser has no node_modules (npm ci --prefix tests/browser)".into());
    }
    Ok(chromium)
}

/// [`tools`]' Chromium, or `None` after printing why `what` is skipped.
pub fn chromium_or_skip(what: &str) -> Option<PathBuf> {
    tools()
        .map_err(|why| eprintln!("SKIPPED {what}: {why}"))
        .ok()
}

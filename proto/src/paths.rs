//! Where bspvt finds files it was not given: one place, resolved at run time (no source path
//! is compiled into a binary).
//!
//! The shared test data (meshes, the HDR map): `$BSPVT_ASSETS` when set, else the first of
//! `../shared/assets` and `../../shared/assets` (from the working directory: the project
//! root, or a crate folder when cargo runs tests), then `../shared/assets` from the
//! executable's folder and up to four folders above it, the first that exists (made
//! absolute); else `../shared/assets` (the error then names it).

use std::path::PathBuf;

/// The environment variable that points at the shared test data.
pub(crate) const ASSETS_ENV: &str = "BSPVT_ASSETS";

/// The shared test-data folder (see the module doc for the order).
pub fn assets_dir() -> PathBuf {
    if let Some(p) = std::env::var_os(ASSETS_ENV) {
        return PathBuf::from(p);
    }
    let mut candidates = vec![
        PathBuf::from("../shared/assets"),
        PathBuf::from("../../shared/assets"),
        PathBuf::from("../../../shared/assets"),
    ];
    // Next to the checkout a binary was built in
    // (`<checkout>/target/release/bspvt` → `<checkout>/../shared/assets`).
    if let Some(exe) = std::env::current_exe()
        .ok()
        .and_then(|e| e.canonicalize().ok())
    {
        for dir in exe.ancestors().skip(1).take(5) {
            candidates.push(dir.join("../shared/assets"));
        }
    }
    candidates
        .into_iter()
        .find(|p| p.is_dir())
        .map(|p| p.canonicalize().unwrap_or(p))
        .unwrap_or_else(|| PathBuf::from("../shared/assets"))
}

/// `assets_dir()/meshes`.
pub fn meshes_dir() -> PathBuf {
    assets_dir().join("meshes")
}

/// The default environment map, `assets_dir()/env/royal_esplanade_1k.hdr`.
pub fn default_env_map() -> PathBuf {
    assets_dir().join("env/royal_esplanade_1k.hdr")
}

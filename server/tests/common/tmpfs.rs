//! A size-limited filesystem for the full-disk tests: a tmpfs mounted by the test (root or
//! passwordless sudo; `None` otherwise, and the test skips with a message).

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A tmpfs of `size` mounted at `at`; unmounted on drop.
pub struct Tmpfs(pub PathBuf);

impl Tmpfs {
    pub fn mount(at: &Path, size: &str) -> Option<Tmpfs> {
        std::fs::create_dir_all(at).ok()?;
        let opts = format!("size={size}");
        let direct = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &opts, "tmpfs"])
            .arg(at)
            .output();
        let ok = direct.is_ok_and(|o| o.status.success())
            || Command::new("sudo")
                .args(["-n", "mount", "-t", "tmpfs", "-o", &opts, "tmpfs"])
                .arg(at)
                .output()
                .is_ok_and(|o| o.status.success());
        ok.then(|| Tmpfs(at.to_path_buf()))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let direct = Command::new("umount").arg(&self.0).output();
        if !direct.is_ok_and(|o| o.status.success()) {
            let _ = Command::new("sudo")
                .args(["-n", "umount"])
                .arg(&self.0)
                .output();
        }
    }
}

/// Writes `path` until the filesystem is full; returns the bytes written.
pub fn fill(path: &Path) -> u64 {
    let mut f = std::fs::File::create(path).unwrap();
    let block = vec![0xa5u8; 64 << 10];
    let mut n = 0u64;
    loop {
        match f.write(&block) {
            Ok(0) => break,
            Ok(k) => n += k as u64,
            Err(e) => {
                assert_eq!(e.kind(), std::io::ErrorKind::StorageFull, "{e}");
                break;
            }
        }
    }
    let _ = f.sync_all();
    n
}

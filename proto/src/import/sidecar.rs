//! An asset's other files: an OBJ's material libraries and their textures, a glTF's external
//! buffers and images. They are read from the folder beside the asset (a file on disk) or from
//! the files uploaded with it (the service), through one gate:
//!
//! - only a relative path below the asset is accepted ([`sidecar_name`]): never an absolute
//!   path, `..`, a drive or a URI scheme, so no file outside the asset's folder is read;
//! - a file larger than the caller's cap is refused before it is read;
//! - every file read is logged ([`Sidecars::into_read`]): a client loads the asset on its own
//!   disk to learn which files to upload with it, and uploads exactly those.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

/// Why an asset's other file was not read.
#[derive(Debug)]
pub(crate) enum SidecarError {
    /// The name is not a relative path below the asset.
    NotBeside,
    /// The asset was uploaded and this file was not uploaded with it.
    NotUploaded(String),
    /// The file is larger than the cap (its size in bytes).
    TooLarge(u64),
    /// The file on disk (its path) cannot be read.
    Io(String, std::io::Error),
}

impl std::fmt::Display for SidecarError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SidecarError::NotBeside => write!(
                f,
                "only files beside the asset are read (not an absolute path, `..` or a URI)"
            ),
            SidecarError::NotUploaded(name) => write!(
                f,
                "it was not uploaded with the asset (send it as a `file` field named {name:?})"
            ),
            SidecarError::TooLarge(bytes) => write!(f, "{bytes} bytes is over the limit"),
            SidecarError::Io(path, e) => write!(f, "{path}: {e}"),
        }
    }
}

/// `name` as a path below the asset's folder, `/`-separated (`\` is read as `/`), or `None`
/// when it is empty, absolute, or has an empty, `.`, `..` or drive/scheme (`:`) component.
pub fn sidecar_name(name: &str) -> Option<String> {
    let parts: Vec<&str> = name.split(['/', '\\']).collect();
    let ok = parts
        .iter()
        .all(|p| !p.is_empty() && *p != "." && *p != ".." && !p.contains([':', '\0']));
    ok.then(|| parts.join("/"))
}

/// Where an asset's other files come from, and the log of those read.
pub(crate) struct Sidecars<'a> {
    place: Place<'a>,
    read: RefCell<Vec<String>>,
}

enum Place<'a> {
    /// The folder the asset file lies in.
    Dir(&'a Path),
    /// The files uploaded with the asset, by [`sidecar_name`].
    Uploaded(&'a BTreeMap<String, Vec<u8>>),
}

impl<'a> Sidecars<'a> {
    /// The files beside an asset on disk.
    pub(crate) fn dir(dir: &'a Path) -> Sidecars<'a> {
        Sidecars {
            place: Place::Dir(dir),
            read: RefCell::default(),
        }
    }

    /// The files uploaded with an asset (keys already [`sidecar_name`]s).
    pub(crate) fn uploaded(files: &'a BTreeMap<String, Vec<u8>>) -> Sidecars<'a> {
        Sidecars {
            place: Place::Uploaded(files),
            read: RefCell::default(),
        }
    }

    /// The bytes of `name` (relative to the asset), refused above `max_bytes`.
    pub(crate) fn read(&self, name: &str, max_bytes: u64) -> Result<Vec<u8>, SidecarError> {
        let name = sidecar_name(name).ok_or(SidecarError::NotBeside)?;
        let bytes = match &self.place {
            Place::Dir(dir) => {
                let path = dir.join(&name);
                let io = |e| SidecarError::Io(path.display().to_string(), e);
                let len = std::fs::metadata(&path).map_err(io)?.len();
                if len > max_bytes {
                    return Err(SidecarError::TooLarge(len));
                }
                std::fs::read(&path).map_err(io)?
            }
            Place::Uploaded(files) => files
                .get(&name)
                .ok_or_else(|| SidecarError::NotUploaded(name.clone()))?
                .clone(),
        };
        if bytes.len() as u64 > max_bytes {
            return Err(SidecarError::TooLarge(bytes.len() as u64));
        }
        let mut read = self.read.borrow_mut();
        if !read.contains(&name) {
            read.push(name);
        }
        Ok(bytes)
    }

    /// The names of the files read, in the order first read.
    pub(crate) fn into_read(self) -> Vec<String> {
        self.read.into_inner()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_paths_below_the_asset_are_names() {
        assert_eq!(sidecar_name("a.mtl").as_deref(), Some("a.mtl"));
        assert_eq!(
            sidecar_name("tex\\wood.png").as_deref(),
            Some("tex/wood.png")
        );
        for bad in [
            "",
            "/etc/passwd",
            "../a.mtl",
            "a/../b",
            "./a",
            "C:\\a",
            "c:a",
            "http://x/a",
            "a//b",
            "a\0b",
        ] {
            assert_eq!(sidecar_name(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn uploaded_files_are_read_logged_once_and_capped() {
        let files = BTreeMap::from([("m/a.mtl".to_string(), b"newmtl a".to_vec())]);
        let s = Sidecars::uploaded(&files);
        assert_eq!(s.read("m\\a.mtl", 100).expect("read"), b"newmtl a");
        assert_eq!(s.read("m/a.mtl", 100).expect("read"), b"newmtl a");
        assert!(matches!(
            s.read("m/a.mtl", 3),
            Err(SidecarError::TooLarge(8))
        ));
        let missing = s.read("b.png", 100).expect_err("not uploaded");
        assert!(missing.to_string().contains("`file` field named \"b.png\""));
        assert!(matches!(s.read("../a", 100), Err(SidecarError::NotBeside)));
        assert_eq!(s.into_read(), ["m/a.mtl"]);
    }
}

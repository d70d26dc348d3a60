//! The dependency rules of ARCHITECTURE.md, checked on the source: no module cycles between
//! the top-level modules of a crate, shading kernels free of I/O, a client library that never
//! reaches the service or the command line, no source path compiled into a binary.
//!
//! A `crate::NAME` (or, inside a folder module, `super::NAME`) path in a module's code is a
//! dependency on `NAME`; comment lines and `#[cfg(test)] mod tests` blocks are left out.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `.rs` files under `dir`, recursively.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.filter_map(Result::ok) {
        let p = e.path();
        if p.is_dir() {
            out.extend(rust_files(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// A file's code: no comment lines, nothing from its `#[cfg(test)]` module on.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => &text,
    };
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Identifiers that follow `prefix` in `text` (e.g. every `X` of `crate::X`).
fn after(text: &str, prefix: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (i, _) in text.match_indices(prefix) {
        let before = text[..i].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        let rest = &text[i + prefix.len()..];
        let id: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !id.is_empty() {
            out.insert(id);
        }
    }
    out
}

/// The top-level modules of the module folder `dir` (a crate's `src`, or a folder module)
/// and, for each, the modules of the same level it uses.
fn module_graph(dir: &Path, prefix: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut mods = BTreeMap::new();
    for e in std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(Result::ok)
    {
        let p = e.path();
        let name = p
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("")
            .to_string();
        if p.is_dir() {
            mods.insert(name, rust_files(&p));
        } else if p.extension().is_some_and(|x| x == "rs")
            && !["lib", "main", "mod"].contains(&name.as_str())
        {
            mods.insert(name, vec![p]);
        }
    }
    let names: BTreeSet<String> = mods.keys().cloned().collect();
    mods.iter()
        .map(|(m, files)| {
            let mut uses = BTreeSet::new();
            for f in files {
                let c = code(f);
                for id in after(&c, prefix) {
                    if names.contains(&id) && &id != m {
                        uses.insert(id);
                    }
                }
            }
            (m.clone(), uses)
        })
        .collect()
}

/// The cycles of `g` (strongly connected components of more than one module).
fn cycles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    // Reachability closure: small graphs, so Floyd–Warshall style is plenty.
    let names: Vec<&String> = g.keys().collect();
    let idx: BTreeMap<&String, usize> = names.iter().enumerate().map(|(i, n)| (*n, i)).collect();
    let n = names.len();
    let mut reach = vec![vec![false; n]; n];
    for (a, uses) in g {
        for b in uses {
            reach[idx[a]][idx[b]] = true;
        }
    }
    for k in 0..n {
        let via = reach[k].clone();
        for row in reach.iter_mut() {
            if row[k] {
                for (r, &v) in row.iter_mut().zip(&via) {
                    *r |= v;
                }
            }
        }
    }
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    for i in 0..n {
        if seen[i] {
            continue;
        }
        let comp: Vec<usize> = (0..n)
            .filter(|&j| j == i || (reach[i][j] && reach[j][i]))
            .collect();
        for &j in &comp {
            seen[j] = true;
        }
        if comp.len() > 1 {
            out.push(comp.iter().map(|&j| names[j].clone()).collect());
        }
    }
    out
}

#[test]
fn no_module_cycles_between_the_top_level_modules_of_any_crate() {
    let r = root();
    let crates = [
        ("proto/src", "crate::"),
        ("proto/shaders/src", "crate::"),
        ("server/bake/src", "crate::"),
        ("server/src", "crate::"),
        ("server/src/service", "super::"),
        ("client/src", "crate::"),
        ("client/lab/src", "crate::"),
        ("client/cli/src", "crate::"),
    ];
    let mut found = Vec::new();
    for (dir, prefix) in crates {
        let g = module_graph(&r.join(dir), prefix);
        assert!(!g.is_empty(), "no modules found in {dir}");
        for c in cycles(&g) {
            found.push(format!("{dir}: {}", c.join(" ↔ ")));
        }
    }
    assert!(found.is_empty(), "module cycles:\n{}", found.join("\n"));
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let mut g = BTreeMap::new();
    g.insert("a".to_string(), BTreeSet::from(["b".to_string()]));
    g.insert("b".to_string(), BTreeSet::from(["c".to_string()]));
    g.insert("c".to_string(), BTreeSet::from(["a".to_string()]));
    g.insert("d".to_string(), BTreeSet::from(["a".to_string()]));
    assert_eq!(cycles(&g), vec![vec!["a", "b", "c"]]);
    assert_eq!(
        after("use crate::x::y; crate::z(); foo::crate::no", "crate::"),
        BTreeSet::from(["x".to_string(), "z".to_string()])
    );
}

/// Shading kernels take and return data: no files, sockets, streaming, windows or sessions.
#[test]
fn shading_kernels_do_no_io() {
    let r = root().join("client/src");
    let kernels = [
        "../../proto/shaders/src",
        "ltc/polygon.rs",
        "shade",
        "texture.rs",
        "frame/shading.rs",
        "sg/lobe.rs",
        "sg/halfspace.rs",
        "sg/brdf.rs",
        "sg/diffuse.rs",
        "sg/ssdf.rs",
    ];
    let forbidden = [
        "std::fs",
        "std::net",
        "File::",
        "ureq::",
        "crate::stream",
        "crate::session",
        "crate::viewer",
        "crate::method",
        "image::open",
        "winit",
        "softbuffer",
    ];
    let mut bad = Vec::new();
    for k in kernels {
        let p = r.join(k);
        let files = if p.is_dir() { rust_files(&p) } else { vec![p] };
        assert!(!files.is_empty(), "kernel {k} not found");
        for f in files {
            let c = code(&f);
            for w in forbidden {
                if c.contains(w) {
                    bad.push(format!("{}: {w}", f.display()));
                }
            }
        }
    }
    assert!(bad.is_empty(), "kernels doing I/O:\n{}", bad.join("\n"));
}

/// The client library builds without the service, axum, a database or clap; the lab and the
/// command line build on it, never the other way.
#[test]
fn the_client_library_depends_on_neither_the_service_nor_the_command_line() {
    let r = root();
    let manifest = std::fs::read_to_string(r.join("client/Cargo.toml")).expect("manifest");
    let normal = manifest
        .split("[dev-dependencies]")
        .next()
        .unwrap_or_default();
    for dep in [
        "bspvt-server",
        "axum",
        "rusqlite",
        "clap",
        "bspvt-lab",
        "tokio",
    ] {
        assert!(
            !normal.lines().any(|l| l.trim_start().starts_with(dep)),
            "client/Cargo.toml depends on {dep}"
        );
    }
    let mut bad = Vec::new();
    for f in rust_files(&r.join("client/src")) {
        let c = code(&f);
        for w in ["bspvt_server", "bspvt_lab", "clap::", "axum", "rusqlite"] {
            if c.contains(w) {
                bad.push(format!("{}: {w}", f.display()));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // The shared shading builds on proto and the ray caster only: no service, client or GPU
    // API (its shaders are text; wgpu and WebGPU compile them).
    let shaders = std::fs::read_to_string(r.join("proto/shaders/Cargo.toml")).expect("manifest");
    for line in shaders.lines().map(str::trim_start) {
        for dep in [
            "bspvt-server",
            "bspvt-client",
            "bspvt-lab",
            "wgpu",
            "axum",
            "tokio",
        ] {
            assert!(
                !line.starts_with(dep),
                "proto/shaders/Cargo.toml depends on {dep}"
            );
        }
    }
    let proto = std::fs::read_to_string(r.join("proto/Cargo.toml")).expect("manifest");
    for dep in ["bspvt-", "axum", "rusqlite", "tokio"] {
        assert!(
            !proto
                .split("[dev-dependencies]")
                .next()
                .unwrap_or_default()
                .lines()
                .any(|l| l.trim_start().starts_with(dep)),
            "proto/Cargo.toml depends on {dep}"
        );
    }
}

/// Assets are found at run time (flag, `BSPVT_ASSETS`, `../shared/assets`): no source path is
/// compiled into a library or binary.
#[test]
fn no_source_path_is_compiled_into_a_binary() {
    let r = root();
    let mut bad = Vec::new();
    for dir in [
        "proto/src",
        "proto/raytrace/src",
        "proto/shaders/src",
        "server/bake/src",
        "server/src",
        "client/src",
        "client/lab/src",
        "client/cli/src",
    ] {
        for f in rust_files(&r.join(dir)) {
            if code(&f).contains("CARGO_MANIFEST_DIR") {
                bad.push(f.display().to_string());
            }
        }
    }
    assert!(bad.is_empty(), "CARGO_MANIFEST_DIR in {}", bad.join(", "));
}

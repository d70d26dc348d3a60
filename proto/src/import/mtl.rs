//! Wavefront MTL material libraries (what an OBJ's `mtllib` names), read by hand like the OBJ.
//!
//! Read: `newmtl`, `Kd` (diffuse albedo), `Ks` (specular colour, used as F0), `Ns` (Phong
//! exponent), `Ke` (emitted radiance: the face is a lamp), `Pr` (PBR roughness, when an
//! exporter writes it), `map_Kd` (a PNG or JPEG next to the OBJ: albedo = `Kd` × texture,
//! sRGB; its options such as `-s`/`-o` are not read, only the file name, its last word).
//! Everything else is ignored; other texture maps (`map_Ks`, `bump`, `disp`, `refl`, …) and
//! transparency (`d` < 1, `Tr` > 0) are reported as warnings, once per kind.
//!
//! **Ns → GGX α.** `α = sqrt(2 / (Ns + 2))`, Walter et al. 2007 §5.2's equivalence between a
//! Phong lobe of exponent Ns and a Beckmann lobe of roughness α, which GGX matches closely at
//! the small α where the choice matters; Ns = 0 gives α = 1, Ns = 1000 gives α ≈ 0.045. `Pr`,
//! where present, is a perceptual roughness and wins: α = Pr². α is clamped to [1e-3, 1].
//! Without `Ks`, F0 = 0.04 (a dielectric); with it, F0 = Ks clamped to [0, 1].

use std::collections::{BTreeSet, HashMap};

use super::FileMaterial;
use crate::material::Material;

/// Smallest GGX α an imported material gets (a mirror is not representable by the LTC fit).
pub(crate) const MIN_ALPHA: f32 = 1e-3;

/// One `newmtl` block as read.
#[derive(Clone, Debug, Default)]
struct Entry {
    kd: Option<[f32; 3]>,
    ks: Option<[f32; 3]>,
    ns: Option<f32>,
    pr: Option<f32>,
    ke: Option<[f32; 3]>,
    map_kd: Option<String>,
}

/// A parsed library: materials by name, and what was ignored.
#[derive(Debug, Default)]
pub(crate) struct Library {
    entries: HashMap<String, Entry>,
    /// Ignored keywords, sorted (`map_Kd`, `d < 1`, …).
    pub ignored: BTreeSet<String>,
}

impl Library {
    /// Parses MTL text. Never fails: a line that cannot be read is ignored and named in
    /// [`Library::ignored`] (a material file never stops a mesh from loading).
    pub(crate) fn parse(bytes: &[u8]) -> Library {
        let mut lib = Library::default();
        let mut current: Option<String> = None;
        for raw in bytes.split(|&b| b == b'\n') {
            let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
            let line = match raw.iter().position(|&b| b == b'#') {
                Some(i) => &raw[..i],
                None => raw,
            };
            let Ok(line) = std::str::from_utf8(line) else {
                lib.ignored.insert("a line that is not UTF-8".into());
                continue;
            };
            let mut words = line.split_ascii_whitespace();
            let Some(key) = words.next() else { continue };
            let rest: Vec<&str> = words.collect();
            if key == "newmtl" {
                let name = rest.join(" ");
                lib.entries.entry(name.clone()).or_default();
                current = Some(name);
                continue;
            }
            let Some(entry) = current.as_ref().and_then(|n| lib.entries.get_mut(n)) else {
                continue;
            };
            let rgb = |r: &[&str]| -> Option<[f32; 3]> {
                let v: Vec<f32> = r.iter().map_while(|w| w.parse().ok()).collect();
                let c = match v.len() {
                    1 => [v[0]; 3],
                    n if n >= 3 => [v[0], v[1], v[2]],
                    _ => return None,
                };
                c.iter().all(|x| x.is_finite()).then_some(c)
            };
            let scalar = |r: &[&str]| -> Option<f32> {
                r.first()?.parse().ok().filter(|x: &f32| x.is_finite())
            };
            let bad = |lib: &mut Library, k: &str| {
                lib.ignored.insert(format!("{k} (unreadable value)"));
            };
            match key {
                "Kd" => match rgb(&rest) {
                    Some(c) => entry.kd = Some(c),
                    None => bad(&mut lib, key),
                },
                "Ks" => match rgb(&rest) {
                    Some(c) => entry.ks = Some(c),
                    None => bad(&mut lib, key),
                },
                "Ke" => match rgb(&rest) {
                    Some(c) => entry.ke = Some(c),
                    None => bad(&mut lib, key),
                },
                "Ns" => match scalar(&rest) {
                    Some(x) => entry.ns = Some(x),
                    None => bad(&mut lib, key),
                },
                "Pr" => match scalar(&rest) {
                    Some(x) => entry.pr = Some(x),
                    None => bad(&mut lib, key),
                },
                "d" if scalar(&rest).is_some_and(|d| d < 1.0) => {
                    lib.ignored.insert("transparency (d < 1)".into());
                }
                "Tr" if scalar(&rest).is_some_and(|t| t > 0.0) => {
                    lib.ignored.insert("transparency (Tr > 0)".into());
                }
                "map_Kd" => match rest.last() {
                    Some(file) => {
                        if rest.len() > 1 {
                            lib.ignored
                                .insert("map_Kd options (only the file is read)".into());
                        }
                        entry.map_kd = Some((*file).to_string());
                    }
                    None => bad(&mut lib, key),
                },
                k if k.starts_with("map_")
                    || matches!(k, "bump" | "disp" | "decal" | "refl" | "norm") =>
                {
                    lib.ignored.insert(format!("texture {k}"));
                }
                _ => {}
            }
        }
        lib
    }

    /// The `map_Kd` file of material `name`, if it names one.
    pub(crate) fn map_kd(&self, name: &str) -> Option<&str> {
        self.entries.get(name)?.map_kd.as_deref()
    }

    /// The material named `name`, mapped to bspvt's GGX model (see the module documentation).
    pub(crate) fn material(&self, name: &str) -> Option<FileMaterial> {
        let e = self.entries.get(name)?;
        let unit = |c: [f32; 3]| c.map(|x| x.clamp(0.0, 1.0));
        let alpha = match (e.pr, e.ns) {
            (Some(pr), _) => pr * pr,
            (None, Some(ns)) => (2.0 / (ns.max(0.0) + 2.0)).sqrt(),
            (None, None) => Material::default().roughness,
        };
        Some(FileMaterial {
            material: Material {
                name: name.to_string(),
                roughness: alpha.clamp(MIN_ALPHA, 1.0),
                albedo: e.kd.map_or(Material::default().albedo, unit),
                specular: e.ks.map_or([0.04; 3], unit),
                maps: None,
                cutout: None,
                normal_map: None,
            },
            emission: e.ke.map_or([0.0; 3], |c| c.map(|x| x.max(0.0))),
            two_sided: false,
            emissive_texture: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_cornell_light_and_a_glossy_material() {
        let text =
            b"# lib\r\nnewmtl light\r\nKd 0.78 0.78 0.78\r\nKe 17 12 4\r\n\r\nnewmtl shiny\r\n\
Kd 0.1 0.2 0.3\r\nKs 0.5 0.5 0.5\r\nNs 98\r\nmap_Kd wood.png\r\nd 0.5\r\n";
        let lib = Library::parse(text);
        let light = lib.material("light").expect("light");
        assert_eq!(light.emission, [17.0, 12.0, 4.0]);
        let shiny = lib.material("shiny").expect("shiny");
        assert_eq!(shiny.material.albedo, [0.1, 0.2, 0.3]);
        assert_eq!(shiny.material.specular, [0.5; 3]);
        // α = sqrt(2 / 100).
        assert!((shiny.material.roughness - 0.141_421_36).abs() < 1e-6);
        assert_eq!(shiny.emission, [0.0; 3]);
        assert_eq!(lib.map_kd("shiny"), Some("wood.png"));
        assert!(lib.map_kd("light").is_none());
        assert!(lib.ignored.contains("transparency (d < 1)"));
        assert!(lib.material("absent").is_none());
    }

    #[test]
    fn hostile_values_do_not_escape_the_valid_range() {
        let lib = Library::parse(b"newmtl x\nKd 9 -1 nan\nKs inf\nNs -5\nKe -3 1e40 2\n");
        let x = lib.material("x").expect("x");
        assert!(x.material.validate(0).is_ok(), "{:?}", x.material);
        assert!(x.emission.iter().all(|e| e.is_finite() && *e >= 0.0));
        assert!(!lib.ignored.is_empty());
    }
}

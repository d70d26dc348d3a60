//! Materials as the resolve pass reads them (`resolve.wgsl`, `surface_material`): five vec4
//! per material and the textures they sample (RGBA8, one `u32` per texel), so per-pixel frames
//! evaluate a textured material at the pixel's UV as the CPU does
//! ([`bspvt_proto::material::MaterialMaps`]: glTF metallic-roughness, OBJ `map_Kd`; a normal
//! map, [`bspvt_proto::scene::NormalMap`]).

use std::collections::HashMap;

use bspvt_proto::scene::{Material, MaterialMaps};
use bspvt_proto::texture::{TextureRef, UvTransform, Wrap};

/// `resolve.wgsl`'s wrap modes: u in bits 0–3, v in bits 4–7.
fn wrap_bits(w: [Wrap; 2]) -> u32 {
    let one = |w: Wrap| match w {
        Wrap::Repeat => 0u32,
        Wrap::Clamp => 1,
        Wrap::Mirror => 2,
    };
    one(w[0]) | one(w[1]) << 4
}

/// A texture use: the image, its wrap modes, its UV transform and whether it is a colour
/// texture (its mip levels are filtered in linear).
type TextureKey = (usize, u32, Option<[u32; 6]>, bool);

/// The index + 1 of texture use `t` (the image and its wrap modes), added on first use; 0 for
/// none.
fn use_of<'m>(
    t: Option<&'m TextureRef>,
    srgb: bool,
    uses: &mut Vec<(&'m TextureRef, bool)>,
    index: &mut HashMap<TextureKey, u32>,
) -> u32 {
    let Some(t) = t else { return 0 };
    let key = (
        std::sync::Arc::as_ptr(&t.texture) as usize,
        wrap_bits(t.wrap),
        t.transform.map(|x| x.matrix().map(f32::to_bits)),
        srgb,
    );
    *index.entry(key).or_insert_with(|| {
        uses.push((t, srgb));
        uses.len() as u32
    })
}

/// Words per texture use's header (`resolve.wgsl`'s `surface_sample`).
const HEADER: usize = 12;

/// `resolve.wgsl`'s material kinds.
const CONSTANT: f32 = 0.0;
const METALLIC_ROUGHNESS: f32 = 1.0;
const DIFFUSE_MAP: f32 = 2.0;

/// Vec4 records per material.
pub const RECORDS: usize = 5;

/// The material records and the texture words. Per material: (albedo, α), (F0, kind),
/// then for metallic-roughness (base colour factor), (metallic, roughness, base colour
/// texture + 1, metallic-roughness texture + 1), for `map_Kd` (Kd, 0), (0, 0, texture + 1, 0);
/// last (normal map texture + 1, its scale, 0, 0); texture indices as u32 bits, 0 for none. Texture words: a header of [`HEADER`] words per
/// texture use — width, height, offset, wrap u | wrap v << 4, then the UV transform
/// (`UvTransform::matrix`: a, b, c, d, tx, ty as f32 bits; the identity's when none), the
/// number n of mip levels below the finest, one unused —, then the texels (R | G << 8 |
/// B << 16 | A << 24) of the finest level and of the n levels below it (`Texture::mip_levels`
/// for the use's encoding: colour textures filter in linear), each half the one before.
/// `uvs`: whether the mesh has texture coordinates (without, every material is its constant
/// fields, as on the CPU); `texels`: whether to build the texture words (the records alone
/// when only the materials' constants changed: the texture indices do not depend on them).
pub fn tables(materials: &[Material], uvs: bool, texels: bool) -> (Vec<[f32; 4]>, Vec<u32>) {
    let bits = |x: u32| f32::from_bits(x);
    let mut uses: Vec<(&TextureRef, bool)> = Vec::new();
    let mut index: HashMap<TextureKey, u32> = HashMap::new();
    let mut records = Vec::with_capacity(RECORDS * materials.len().max(1));
    for m in materials {
        let c = |k: f32| {
            [
                [m.albedo[0], m.albedo[1], m.albedo[2], m.roughness],
                [m.specular[0], m.specular[1], m.specular[2], k],
            ]
        };
        match (&m.maps, uvs) {
            (
                Some(MaterialMaps::MetallicRoughness {
                    base_color,
                    metallic,
                    roughness,
                    base_color_texture,
                    metallic_roughness_texture,
                }),
                true,
            ) => {
                records.extend(c(METALLIC_ROUGHNESS));
                records.push([base_color[0], base_color[1], base_color[2], 0.0]);
                let bc = use_of(base_color_texture.as_ref(), true, &mut uses, &mut index);
                let mr = use_of(
                    metallic_roughness_texture.as_ref(),
                    false,
                    &mut uses,
                    &mut index,
                );
                records.push([*metallic, *roughness, bits(bc), bits(mr)]);
            }
            (Some(MaterialMaps::Diffuse { kd, texture }), true) => {
                records.extend(c(DIFFUSE_MAP));
                records.push([kd[0], kd[1], kd[2], 0.0]);
                let t = use_of(Some(texture), true, &mut uses, &mut index);
                records.push([0.0, 0.0, bits(t), 0.0]);
            }
            _ => {
                records.extend(c(CONSTANT));
                records.extend([[0.0; 4]; 2]);
            }
        }
        match (&m.normal_map, uvs) {
            (Some(n), true) => {
                let t = use_of(Some(&n.texture), false, &mut uses, &mut index);
                records.push([bits(t), n.scale, 0.0, 0.0]);
            }
            _ => records.push([0.0; 4]),
        }
    }
    if records.is_empty() {
        records.extend([[0.0; 4]; RECORDS]);
    }
    let mut words = vec![0u32; HEADER * uses.len()];
    for (k, &(t, srgb)) in uses.iter().enumerate().filter(|_| texels) {
        let tex = &t.texture;
        let levels = tex.mip_levels(srgb);
        let offset = words.len() as u32;
        let m = t
            .transform
            .unwrap_or(UvTransform::IDENTITY)
            .matrix()
            .map(f32::to_bits);
        words[HEADER * k..HEADER * (k + 1)].copy_from_slice(&[
            tex.width,
            tex.height,
            offset,
            wrap_bits(t.wrap),
            m[0],
            m[1],
            m[2],
            m[3],
            m[4],
            m[5],
            levels.len() as u32,
            0,
        ]);
        let texels = |rgba: &[u8]| {
            rgba.chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect::<Vec<_>>()
        };
        words.extend(texels(&tex.rgba));
        for l in levels {
            words.extend(texels(&l.rgba));
        }
    }
    if words.is_empty() {
        words.extend([0; 4]);
    }
    (records, words)
}

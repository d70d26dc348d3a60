//! Built-in procedural scenes: no download needed, enough tessellation to show shadows.
//!
//! `dynamic`: the run-time methods' moving scene (`assets/scenes/dynamic.json`).
//!
//! `room`: the project's own enclosed room (`assets/rooms/room.gltf`, written by
//! `assets/rooms/make_rooms.py`): coloured walls, an emissive ceiling quad, a metal box and a
//! glossy sphere, read by the glTF importer as any asset given alone ([`Scene::from_asset`]).
//!
//! `two-lamps`: the same shell lit by a ceiling lamp and a pendant lamp 1.2 m lower, with a
//! board hung between them (`assets/rooms/two-lamps.gltf`, issue 34).
//!
//! `punctual-room`: the same shell with a window, lit only by `KHR_lights_punctual` lights — a
//! point light, a spot light and a sun through the window (`assets/rooms/punctual-room.gltf`).
//!
//! `plate`: a 160×160 receiver grid (25,600 vertices) under a sphere and a tilted slab, lit by a
//! quad light that may move in a declared box above them (28,258 vertices in all).

use glam::{Quat, Vec3};

use crate::import::Format;
use crate::mesh::{Aabb, Mesh};
use crate::scene::{
    BakeSettings, Camera, Material, MeshRef, PolygonLight, Region, Scene, SceneFile,
};

/// Names accepted by [`scene`] and [`mesh`] (and by `builtin:NAME` in scene files).
pub const NAMES: &[&str] = &[
    "plate",
    "plate-small",
    "dynamic",
    "room",
    "two-lamps",
    "punctual-room",
];

/// Single-object meshes for scene files to place (`builtin:NAME`, with a `transform`):
/// `sphere` (unit radius, 2,562 vertices) and `cube` (unit side, 12 × 12 vertices a face).
pub(crate) const PART_NAMES: &[&str] = &["sphere", "cube"];

/// `dynamic`: a sphere orbiting and bobbing over a floor beside a twisting bar (the
/// run-time methods' moving scene), written as a scene file.
pub const DYNAMIC_JSON: &str = include_str!("../../../assets/scenes/dynamic.json");

/// `room`: the project's glTF room (self-contained: its buffer is a `data:` URI).
const ROOM_GLTF: &[u8] = include_bytes!("../../../assets/rooms/room.gltf");

/// `two-lamps`: the project's two-lamp glTF room (self-contained).
const TWO_LAMPS_GLTF: &[u8] = include_bytes!("../../../assets/rooms/two-lamps.gltf");

/// `punctual-room`: the project's glTF room lit by point, spot and sun lights (self-contained).
const PUNCTUAL_ROOM_GLTF: &[u8] = include_bytes!("../../../assets/rooms/punctual-room.gltf");

/// Every name [`mesh`] accepts.
pub fn mesh_names() -> Vec<&'static str> {
    NAMES.iter().chain(PART_NAMES).copied().collect()
}

/// A built-in mesh: a part, or a built-in scene's mesh (at t = 0).
pub fn mesh(name: &str) -> Option<Mesh> {
    match name {
        "sphere" => Some(icosphere(4, 0)),
        "cube" => Some(cuboid(Vec3::ZERO, Vec3::splat(0.5), Quat::IDENTITY, 12, 0)),
        _ => scene(name).map(|s| s.mesh),
    }
}

/// A built-in scene by name.
pub fn scene(name: &str) -> Option<Scene> {
    match name {
        "plate" => Some(plate(160, 4)),
        // The same layout, coarse enough for fast tests (1,849 + 642 + 96 vertices).
        "plate-small" => Some(plate(43, 3)),
        "dynamic" => Scene::from_json(DYNAMIC_JSON, std::path::Path::new("")).ok(),
        "room" => gltf_scene(ROOM_GLTF),
        "two-lamps" => gltf_scene(TWO_LAMPS_GLTF),
        "punctual-room" => gltf_scene(PUNCTUAL_ROOM_GLTF),
        _ => None,
    }
}

/// A self-contained glTF asset given alone.
fn gltf_scene(bytes: &[u8]) -> Option<Scene> {
    let limits = crate::import::Limits::default();
    let asset = crate::import::load_asset_bytes(bytes, Format::Gltf, &limits);
    asset.ok().and_then(|a| Scene::from_asset(a).ok())
}

/// A built-in scene as a scene file (what a client uploads for it): the scene's own file
/// where it has one, else its mesh as `builtin:NAME` with its lights, materials and camera.
pub fn scene_file(name: &str) -> Option<SceneFile> {
    if name == "dynamic" {
        return serde_json::from_str(DYNAMIC_JSON).ok();
    }
    let s = scene(name)?;
    Some(SceneFile {
        meshes: vec![MeshRef {
            path: format!("builtin:{name}"),
            material: Some(0),
            transform: None,
            motion: None,
        }],
        ground_plane: false,
        ground_material: 0,
        materials: s.materials,
        lights: s.lights,
        punctual: s.punctual,
        suns: s.suns,
        punctual_radius: None,
        asset_lights: true,
        camera: Some(s.camera),
        bake: s.bake,
        environment: s.environment,
    })
}

fn plate(grid: u32, sphere_subdiv: u32) -> Scene {
    let mut mesh = grid_plane(Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Z * 2.0, grid, 0);
    let mut sphere = icosphere(sphere_subdiv, 1);
    for p in &mut sphere.positions {
        *p = *p * 0.5 + Vec3::new(-0.7, 0.9, 0.2);
    }
    mesh.append(&sphere, 0);
    let slab = cuboid(
        Vec3::new(0.7, 1.3, -0.2),
        Vec3::new(0.55, 0.04, 0.4),
        Quat::from_rotation_y(0.5) * Quat::from_rotation_x(0.25),
        4,
        2,
    );
    mesh.append(&slab, 0);
    let (cx, y, cz, s) = (0.0, 3.0, 0.0, 0.5);
    let light = PolygonLight {
        vertices: vec![
            [cx - s, y, cz - s],
            [cx + s, y, cz - s],
            [cx + s, y, cz + s],
            [cx - s, y, cz + s],
        ],
        radiance: [12.0, 11.0, 10.0],
        two_sided: false,
        texture: None,
        region: Some(Region {
            min: [-2.5, 2.0, -2.5],
            max: [2.5, 4.0, 2.5],
        }),
        moves_in_plane: false,
        image: None,
    };
    Scene {
        mesh,
        materials: vec![
            Material {
                name: "floor".into(),
                roughness: 0.35,
                albedo: [0.55, 0.55, 0.52],
                specular: [0.04; 3],
                maps: None,
                cutout: None,
                normal_map: None,
            },
            Material {
                name: "sphere".into(),
                roughness: 0.15,
                albedo: [0.6, 0.15, 0.1],
                specular: [0.05; 3],
                maps: None,
                cutout: None,
                normal_map: None,
            },
            Material {
                name: "slab".into(),
                roughness: 0.5,
                albedo: [0.2, 0.35, 0.6],
                specular: [0.04; 3],
                maps: None,
                cutout: None,
                normal_map: None,
            },
        ],
        lights: vec![light],
        environment: None,
        camera: Camera {
            position: [3.2, 3.0, 4.2],
            target: [0.0, 0.5, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
            aspect: None,
        },
        bake: BakeSettings::default(),
        motion: Vec::new(),
        warnings: Vec::new(),
        punctual: Vec::new(),
        suns: Vec::new(),
    }
}

/// A `n × n`-vertex grid centred at `center`, spanning ±`du` and ±`dv`, facing `du × dv`.
pub fn grid_plane(center: Vec3, du: Vec3, dv: Vec3, n: u32, material: u32) -> Mesh {
    let n = n.max(2);
    let normal = du.cross(dv).normalize();
    let mut m = Mesh::default();
    for j in 0..n {
        for i in 0..n {
            let s = 2.0 * i as f32 / (n - 1) as f32 - 1.0;
            let t = 2.0 * j as f32 / (n - 1) as f32 - 1.0;
            m.positions.push(center + s * du + t * dv);
            m.normals.push(normal);
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            m.triangles.push([a, b, d]);
            m.triangles.push([a, d, c]);
        }
    }
    m.material_ids = vec![material; m.triangles.len()];
    m
}

/// A unit icosphere subdivided `subdiv` times (10·4ⁿ + 2 vertices), smooth normals.
pub fn icosphere(subdiv: u32, material: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut pos: Vec<Vec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|&p| Vec3::from(p).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdiv {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<Vec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push((pos[a as usize] + pos[b as usize]).normalize());
                pos.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    Mesh {
        normals: pos.clone(),
        positions: pos,
        material_ids: vec![material; tris.len()],
        triangles: tris,
        uvs: Vec::new(),
    }
}

/// A box with half extents `half`, rotated by `rot`, each face an `n × n`-vertex grid (hard
/// edges: faces do not share vertices).
pub fn cuboid(center: Vec3, half: Vec3, rot: Quat, n: u32, material: u32) -> Mesh {
    let mut m = Mesh::default();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let mut w = Vec3::ZERO;
            w[axis] = sign;
            let mut a = Vec3::ZERO;
            a[(axis + 1) % 3] = 1.0;
            let mut b = Vec3::ZERO;
            b[(axis + 2) % 3] = sign;
            let face = grid_plane(
                w * half[axis],
                a * half[(axis + 1) % 3],
                b * half[(axis + 2) % 3],
                n,
                material,
            );
            m.append(&face, 0);
        }
    }
    for p in &mut m.positions {
        *p = center + rot * *p;
    }
    for nrm in &mut m.normals {
        *nrm = rot * *nrm;
    }
    m
}

/// A tessellated ground square just under `bounds`, wide enough to catch its shadows.
pub(crate) fn ground_under(bounds: &Aabb, material: u32) -> Mesh {
    let diag = bounds.diagonal().max(1e-6);
    let c = bounds.center();
    let y = bounds.min.y - 1e-3 * diag;
    let half = 1.2 * diag;
    grid_plane(
        Vec3::new(c.x, y, c.z),
        Vec3::X * half,
        Vec3::NEG_Z * half,
        96,
        material,
    )
}

/// A downward-facing square light above `bounds`, off to one side so the shadow shows.
pub(crate) fn quad_light_above(bounds: &Aabb, radiance: [f32; 3]) -> PolygonLight {
    let diag = bounds.diagonal().max(1e-6);
    let c = bounds.center();
    let (x, y, z) = (
        c.x + 0.3 * diag,
        bounds.max.y + 0.8 * diag,
        c.z + 0.2 * diag,
    );
    let s = 0.25 * diag;
    PolygonLight {
        vertices: vec![
            [x - s, y, z - s],
            [x + s, y, z - s],
            [x + s, y, z + s],
            [x - s, y, z + s],
        ],
        radiance,
        two_sided: false,
        texture: None,
        // The default lamp of a bare mesh is the one users drag: it moves in its plane.
        region: None,
        moves_in_plane: true,
        image: None,
    }
}

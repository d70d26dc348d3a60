//! What the client's shading tests share: a small deterministic generator and random BSPVTs
//! (the CPU stability tests and the GPU-against-CPU tests draw the same trees).

#![allow(dead_code, clippy::unwrap_used)]

use bspvt_proto::bspvt::{FaceTree, LineCodec, Node, QLine, VertexTrees};

/// A small deterministic generator (the trees come from a proptest-chosen seed).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let x = self.0;
        (x ^ (x >> 29)).wrapping_mul(0xbf58476d1ce4e5b9) ^ (x >> 32)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A random tree of at most `depth` levels appended to `nodes` (leaves often 0 or 255).
pub fn random_tree(rng: &mut Rng, codec: &LineCodec, depth: u32, nodes: &mut Vec<Node>) {
    if depth == 0 || rng.below(4) == 0 {
        let value = match rng.below(4) {
            0 => 0,
            1 => 255,
            _ => rng.below(256) as u8,
        };
        nodes.push(Node::Leaf { value });
        return;
    }
    let at = nodes.len();
    nodes.push(Node::Leaf { value: 0 });
    let line = QLine {
        angle: rng.below(u64::from(codec.angles())) as u16,
        offset: rng.below(u64::from(codec.offsets())) as u16,
    };
    random_tree(rng, codec, depth - 1, nodes);
    let right = nodes.len() as u32;
    random_tree(rng, codec, depth - 1, nodes);
    nodes[at] = Node::Split { line, right };
}

/// A vertex's random trees (a face absent, i.e. visible, one time in six).
pub fn random_trees(seed: u64, codec: &LineCodec) -> VertexTrees {
    let mut rng = Rng(seed);
    let mut t = VertexTrees::default();
    for f in &mut t.faces {
        if rng.below(6) == 0 {
            continue; // absent face: visible
        }
        let mut nodes = Vec::new();
        random_tree(&mut rng, codec, 7, &mut nodes);
        *f = Some(FaceTree { nodes });
    }
    t
}

/// One frame of `method` with `settings` (its mode among them) through the registry, as
/// `bspvt render` draws it: the scene's lights as loaded, baked `trees` and `sky` trees where
/// given, frame number 7.
pub fn registry_frame(
    method: &str,
    scene: &bspvt_proto::Scene,
    r: &bspvt_client::render::renderer::Renderer,
    settings: &bspvt_client::method::Settings,
    trees: Option<&bspvt_client::render::renderer::Trees>,
    sky: Option<&bspvt_client::render::renderer::Trees>,
) -> bspvt_client::frame::image::Image {
    use bspvt_client::method::{FrameInput, SceneData, registry};
    let data = SceneData::new(scene);
    let mut state = registry::lookup(method)
        .unwrap()
        .prepare(&data, settings)
        .unwrap();
    let lights: Vec<_> = scene
        .lights
        .iter()
        .map(|l| bspvt_client::light::Light::load(l).unwrap())
        .collect();
    state
        .frame(&FrameInput {
            scene: &data,
            renderer: r,
            lights: &lights,
            trees,
            sky_trees: sky,
            env_rotation_deg: 0.0,
            index: 7,
            time: 0.0,
            mode: settings.mode,
            on_gpu: false,
        })
        .unwrap()
        .image
}

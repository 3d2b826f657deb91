//! A mesh with workbench's per-vertex curvature as binary glTF 2.0 (`.glb`), for engines to read
//! the curvature the shading snippets expect (docs/engines.md, "Curvature on a mesh").
//!
//! One mesh, one triangle primitive: POSITION (metres, glTF's unit), NORMAL, `_CDRF_KAPPA` (the
//! curvature in the preset's unit, a float per vertex: glTF's custom-attribute convention) and
//! COLOR_0, whose red, green and blue all hold v, the curvature's texture coordinate
//! (κ − κ_min)/(κ_max − κ_min) clamped to [0, 1], for importers that drop custom attributes.

use serde_json::json;

/// The vertex data, in glTF's units.
pub struct GlbMesh<'a> {
    /// Positions in metres.
    pub positions: &'a [[f32; 3]],
    pub normals: &'a [[f32; 3]],
    /// Curvature per vertex, in the preset's unit.
    pub kappa: &'a [f32],
    /// v per vertex.
    pub v: &'a [f32],
    pub triangles: &'a [[u32; 3]],
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

/// The `.glb` bytes of `m`.
pub fn encode(m: &GlbMesh, generator: &str) -> Vec<u8> {
    let n = m.positions.len();
    assert!(m.normals.len() == n && m.kappa.len() == n && m.v.len() == n);
    let mut bin: Vec<u8> = vec![];
    let mut views = vec![];
    let mut push = |bytes: Vec<u8>, target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(&bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": bytes.len(),
            "target": target,
        }));
        views.len() - 1
    };
    let f32s =
        |v: &mut dyn Iterator<Item = f32>| -> Vec<u8> { v.flat_map(|x| x.to_le_bytes()).collect() };
    let pos = push(
        f32s(&mut m.positions.iter().flatten().copied()),
        ARRAY_BUFFER,
    );
    let nor = push(f32s(&mut m.normals.iter().flatten().copied()), ARRAY_BUFFER);
    let col = push(f32s(&mut m.v.iter().flat_map(|&v| [v, v, v])), ARRAY_BUFFER);
    let kap = push(f32s(&mut m.kappa.iter().copied()), ARRAY_BUFFER);
    let idx = push(
        m.triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect(),
        ELEMENT_ARRAY_BUFFER,
    );
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in m.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let doc = json!({
        "asset": { "version": "2.0", "generator": generator },
        "scene": 0,
        "scenes": [ { "nodes": [0] } ],
        "nodes": [ { "mesh": 0 } ],
        "meshes": [ {
            "primitives": [ {
                "attributes": { "POSITION": 0, "NORMAL": 1, "COLOR_0": 2, "_CDRF_KAPPA": 3 },
                "indices": 4,
                "mode": 4,
            } ],
        } ],
        "buffers": [ { "byteLength": bin.len() } ],
        "bufferViews": views,
        "accessors": [
            { "bufferView": pos, "componentType": FLOAT, "count": n, "type": "VEC3", "min": lo, "max": hi },
            { "bufferView": nor, "componentType": FLOAT, "count": n, "type": "VEC3" },
            { "bufferView": col, "componentType": FLOAT, "count": n, "type": "VEC3" },
            { "bufferView": kap, "componentType": FLOAT, "count": n, "type": "SCALAR" },
            { "bufferView": idx, "componentType": UNSIGNED_INT, "count": 3 * m.triangles.len(), "type": "SCALAR" },
        ],
    });
    let mut text = doc.to_string().into_bytes();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

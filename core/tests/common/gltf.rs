//! A small glTF 2.0 writer for the tests: accessors over one binary buffer, and the document's other parts as
//! JSON text the test writes, saved as a `.gltf` (the buffer in a `data:` URI, or in a file beside it) or a
//! `.glb`.

#![allow(clippy::unwrap_used)]

use std::fmt::Write;
use std::path::Path;

/// One buffer, its views and accessors, and the rest of the document as JSON members.
#[derive(Default)]
pub struct Builder {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
    /// Further top-level members, e.g. `"nodes": [...]`, without the surrounding braces.
    pub members: Vec<String>,
}

impl Builder {
    fn view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(format!(r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{}}}"#, bytes.len()));
        self.views.len() - 1
    }

    /// A `VEC3` float accessor (with the `min` and `max` that POSITION needs); its index.
    pub fn vec3(&mut self, v: &[[f32; 3]]) -> usize {
        let bytes: Vec<u8> = v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in v {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        self.accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC3","min":{lo:?},"max":{hi:?}}}"#,
            v.len()
        ));
        self.accessors.len() - 1
    }

    /// A `VEC4` float accessor (tangents); its index.
    pub fn vec4(&mut self, v: &[[f32; 4]]) -> usize {
        let bytes: Vec<u8> = v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(format!(r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC4"}}"#, v.len()));
        self.accessors.len() - 1
    }

    /// A `VEC2` float accessor; its index.
    pub fn vec2(&mut self, v: &[[f32; 2]]) -> usize {
        let bytes: Vec<u8> = v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(format!(r#"{{"bufferView":{view},"componentType":5126,"count":{},"type":"VEC2"}}"#, v.len()));
        self.accessors.len() - 1
    }

    /// An unsigned-short `SCALAR` accessor (indices); its index.
    pub fn indices(&mut self, v: &[u16]) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes);
        self.accessors
            .push(format!(r#"{{"bufferView":{view},"componentType":5123,"count":{},"type":"SCALAR"}}"#, v.len()));
        self.accessors.len() - 1
    }

    /// A buffer view of raw bytes (an encoded image); its index.
    pub fn bytes(&mut self, bytes: &[u8]) -> usize {
        self.view(bytes)
    }

    /// Adds a top-level member (`"nodes": [...]`).
    pub fn member(&mut self, m: &str) -> &mut Self {
        self.members.push(m.to_string());
        self
    }

    /// The JSON document; `buffer_uri` is the buffer's `uri`, or `None` for a GLB's binary chunk.
    pub fn json(&self, buffer_uri: Option<&str>) -> String {
        let uri = buffer_uri.map(|u| format!(r#","uri":"{u}""#)).unwrap_or_default();
        let mut s = String::from(r#"{"asset":{"version":"2.0"}"#);
        write!(s, r#","buffers":[{{"byteLength":{}{uri}}}]"#, self.bin.len()).unwrap();
        write!(s, r#","bufferViews":[{}]"#, self.views.join(",")).unwrap();
        write!(s, r#","accessors":[{}]"#, self.accessors.join(",")).unwrap();
        for m in &self.members {
            write!(s, ",{m}").unwrap();
        }
        s.push('}');
        s
    }

    /// The binary buffer.
    pub fn bin(&self) -> &[u8] {
        &self.bin
    }

    /// Writes a `.gltf` with the buffer in a base64 `data:` URI.
    pub fn write_gltf(&self, path: &Path) {
        let uri = format!("data:application/octet-stream;base64,{}", base64(&self.bin));
        std::fs::write(path, self.json(Some(&uri))).unwrap();
    }

    /// Writes a `.gltf` whose buffer is the file `bin_name` beside it.
    pub fn write_gltf_with_bin(&self, path: &Path, bin_name: &str) {
        std::fs::write(path, self.json(Some(bin_name))).unwrap();
        std::fs::write(path.with_file_name(bin_name), &self.bin).unwrap();
    }

    /// The bytes of a `.glb`.
    pub fn glb(&self) -> Vec<u8> {
        let mut json = self.json(None).into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}

/// Standard base64 with padding.
pub fn base64(b: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in b.chunks(3) {
        let n =
            (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// A fresh folder for one test's files.
pub fn folder(test: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("photon-gltf-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// One triangle, `(0,0,0)`, `(1,0,0)`, `(0,1,0)`, as mesh 0 (indexed) and mesh 1 (not indexed); meshes JSON.
pub fn unit_triangle_meshes(b: &mut Builder) -> String {
    let p = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let i = b.indices(&[0, 1, 2]);
    let q = b.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    format!(
        r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}},{{"primitives":[{{"attributes":{{"POSITION":{q}}}}}]}}]"#
    )
}

//! A concave OBJ polygon renders as the region it encloses: the L-shaped face of issue 16 and a five-pointed
//! star, each one `f` line, give the same pixels to the bit as the same regions written as explicit triangles
//! (a different triangulation: triangle intersection is watertight, so only coverage decides a pixel), rendered
//! as emitters against black.

#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::render::render_image;
use photon_core::scene::Scene;
use std::path::PathBuf;

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("photon-obj-polygons-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An OBJ of the vertices `v` (in z = 0) and the faces `faces` (1-based).
fn obj(v: &[[f64; 2]], faces: &[Vec<usize>]) -> String {
    let mut s: String = v.iter().map(|p| format!("v {} {} 0\n", p[0], p[1])).collect();
    for f in faces {
        s += &format!("f {}\n", f.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(" "));
    }
    s
}

/// The image of the mesh `obj_text` as a two-sided emitter of radiance 1 against black, seen from +z.
fn render(name: &str, obj_text: &str) -> Vec<f32> {
    let d = dir();
    std::fs::write(d.join(format!("{name}.obj")), obj_text).unwrap();
    let text = format!(
        r#"
[camera]
eye = [0.0, 1.0, 3.0]
look_at = [0.0, 1.0, 0.0]
fov = 60.0
width = 48
height = 48

[render]
spp = 2
integrator = "direct"

[materials.black]
type = "lambert"
albedo = 0.0

[[objects]]
type = "mesh"
file = "{name}.obj"
material = "black"
emission = {{ radiance = [1.0, 1.0, 1.0], two_sided = true }}
"#
    );
    let path = d.join(format!("{name}.toml"));
    std::fs::write(&path, &text).unwrap();
    let scene = Scene::load(&path).unwrap();
    let prep = Prepared::new(&scene, &path).unwrap();
    render_image(&prep, &|_| {}).pixels
}

fn assert_same_bits(a: &[f32], b: &[f32], what: &str) {
    let differ = a.iter().zip(b).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
    assert_eq!(differ, 0, "{what}: {differ} values differ");
    assert!(a.iter().any(|&v| v > 0.0), "{what}: nothing lit");
}

#[test]
fn l_shaped_face_renders_as_its_explicit_triangles() {
    // (1,0) (1,1) (0,1) (0,2) (−1,2) (−1,0); explicit: the bottom bar as two triangles, the top-left square as
    // two more (the extra vertex (−1,1) makes them a different triangulation from any ear clipping).
    let v = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 2.0], [-1.0, 2.0], [-1.0, 0.0], [-1.0, 1.0]];
    let face = render("l-face", &obj(&v[..6], &[vec![1, 2, 3, 4, 5, 6]]));
    let tris = render("l-tris", &obj(&v, &[vec![6, 1, 2], vec![6, 2, 7], vec![7, 3, 4], vec![7, 4, 5]]));
    assert_same_bits(&face, &tris, "L shape");
}

#[test]
fn star_face_renders_as_its_explicit_triangles() {
    // A five-pointed star (outer radius 1, inner 0.4) around (0, 1); explicit: ten triangles from its centre.
    let mut v: Vec<[f64; 2]> = (0..10)
        .map(|i| {
            let a = std::f64::consts::PI * f64::from(i) / 5.0 + std::f64::consts::FRAC_PI_2;
            let r = if i % 2 == 0 { 1.0 } else { 0.4 };
            // Rounded to six decimals so the OBJ text is the same in both files.
            [(r * a.cos() * 1e6).round() / 1e6, ((1.0 + r * a.sin()) * 1e6).round() / 1e6]
        })
        .collect();
    let face = render("star-face", &obj(&v, &[(1..=10).collect()]));
    v.push([0.0, 1.0]);
    let fan: Vec<Vec<usize>> = (0..10).map(|i| vec![11, i + 1, (i + 1) % 10 + 1]).collect();
    let tris = render("star-tris", &obj(&v, &fan));
    assert_same_bits(&face, &tris, "star");
}

//! Every kind of malformed scene gives an error, never a panic, and the message names the file, the line or the
//! field, and what was expected. The shipped scenes and the manual's examples load and prepare.
#![allow(clippy::unwrap_used)]

use photon_core::prepare::Prepared;
use photon_core::scene::{Scene, SceneError};
use std::error::Error;
use std::path::{Path, PathBuf};

/// A valid camera (lines 1–5), so that errors further down have known line numbers.
const CAMERA: &str = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nwidth = 8\nheight = 8\n";
/// A valid material (lines 6–7 after `CAMERA`).
const WHITE: &str = "[materials.white]\ntype = \"lambert\"\n";
/// A valid sphere (lines 8–12 after `CAMERA` and `WHITE`) to append fields to.
const SPHERE: &str = "[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = 0.5\nmaterial = \"white\"\n";

/// The name the parse tests give their scene text.
const FILE: &str = "bad-scene.toml";

/// The message of the error, with its causes as a chain printer (`anyhow`'s `{:#}`) shows them.
fn chain(e: &dyn Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s = format!("{s}: {c}");
        cause = c.source();
    }
    s
}

/// The error of parsing `text`; fails the test if the scene is accepted.
fn parse_err(text: &str) -> String {
    match Scene::parse(text, Path::new("scenes").join(FILE).as_path()) {
        Ok(_) => panic!("accepted a malformed scene:\n{text}"),
        Err(e) => chain(&e),
    }
}

/// Asserts that `msg` names the scene file and contains every one of `parts`.
fn assert_names(msg: &str, parts: &[&str]) {
    assert!(msg.contains(FILE), "the file is not named in: {msg}");
    for p in parts {
        assert!(msg.contains(p), "`{p}` missing from: {msg}");
    }
}

/// A fresh folder for one test under the system's temporary folder.
fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("photon-scene-errors-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    dir
}

/// Writes `obj` as `meshes/NAME` (unless `None`) beside a scene that uses it, loads and prepares the scene, and
/// returns the error with its causes.
fn mesh_err(test: &str, name: &str, obj: Option<&str>) -> String {
    let dir = temp_dir(test);
    if let Some(obj) = obj {
        std::fs::write(dir.join("meshes").join(name), obj).unwrap();
    }
    let scene_path = dir.join("scene.toml");
    let text = format!("{CAMERA}{WHITE}[[objects]]\ntype = \"mesh\"\nfile = \"meshes/{name}\"\nmaterial = \"white\"\n");
    std::fs::write(&scene_path, text).unwrap();
    // The scene itself is valid: the mesh is read when the scene is prepared.
    let scene = Scene::load(&scene_path).unwrap();
    let result = Prepared::new(&scene, &scene_path);
    let _ = std::fs::remove_dir_all(&dir);
    match result {
        Ok(_) => panic!("accepted a malformed mesh:\n{obj:?}"),
        Err(e) => {
            assert!(matches!(e, SceneError::Mesh { .. }), "{e:?}");
            let msg = chain(&e);
            assert!(msg.contains("scene.toml") && msg.contains("objects[0].file"), "{msg}");
            msg
        }
    }
}

#[test]
fn toml_syntax_error_gives_the_line() {
    let msg = parse_err(&format!("{CAMERA}{WHITE}[[objects]\ntype = \"sphere\"\n"));
    assert_names(&msg, &["line 8", "expected `]`"]);
    let msg = parse_err(&format!("{CAMERA}[render]\nspp = 4\nspp = 5\n"));
    assert_names(&msg, &["line 8", "duplicate key"]);
    let msg = parse_err("[camera]\neye = [0.0, 1.0\n");
    assert_names(&msg, &["line 2"]);
}

#[test]
fn unknown_fields_are_errors_that_name_the_field_and_the_line() {
    let cases = [
        (format!("colour = 1\n{CAMERA}"), "line 1", "`colour`", "`camera`"),
        (format!("{CAMERA}zoom = 2.0\n"), "line 6", "`zoom`", "`focus_distance`"),
        (format!("{CAMERA}[render]\nsamples = 4\n"), "line 7", "`samples`", "`spp`"),
        (format!("{CAMERA}[render.photons]\nglobals = 4\n"), "line 7", "`globals`", "`global`"),
        (format!("{CAMERA}{WHITE}{SPHERE}colour = 3\n"), "line 8", "`colour`", "`radius`"),
        (format!("{CAMERA}{WHITE}albedo = 0.5\nshiny = true\n"), "line 6", "`shiny`", "`albedo`"),
        (
            format!("{CAMERA}{WHITE}{SPHERE}emission = {{ radiance = [1, 1, 1], both = true }}\n"),
            "line 8",
            "`both`",
            "`two_sided`",
        ),
        (
            format!("{CAMERA}[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\ncolor = [1, 1, 1]\n"),
            "line 6",
            "`color`",
            "`power`",
        ),
    ];
    for (text, line, field, expected) in cases {
        assert_names(&parse_err(&text), &[line, "unknown field", field, expected]);
    }
}

#[test]
fn unknown_types_and_integrators_list_the_choices() {
    let msg = parse_err(&format!("{CAMERA}{WHITE}[[objects]]\ntype = \"cube\"\nmaterial = \"white\"\n"));
    assert_names(&msg, &["line 9", "`cube`", "`sphere`", "`mesh`"]);
    let msg = parse_err(&format!("{CAMERA}[materials.gold]\ntype = \"metal\"\n"));
    assert_names(&msg, &["line 7", "`metal`", "`lambert`", "`dielectric`"]);
    let msg = parse_err(&format!("{CAMERA}[render]\nintegrator = \"bidir\"\n"));
    assert_names(&msg, &["line 7", "`bidir`", "`path`"]);
    let msg = parse_err(&format!("{CAMERA}[render.photons]\nkernel = \"triangle\"\n"));
    assert_names(&msg, &["line 7", "`triangle`", "`epanechnikov`"]);
}

#[test]
fn wrong_types_say_what_was_expected() {
    let cases = [
        (format!("{CAMERA}[render]\nspp = \"many\"\n"), "line 7", "expected u32"),
        (format!("{CAMERA}fov = \"wide\"\n"), "line 6", "expected f32"),
        (format!("{CAMERA}{WHITE}{SPHERE}").replace("radius = 0.5", "radius = \"big\""), "line 8", "expected f32"),
        (CAMERA.replace("eye = [0.0, 1.0, 3.0]", "eye = [0.0, 1.0]"), "line 2", "3"),
        (format!("{CAMERA}{WHITE}{SPHERE}emission = [1.0, 1.0, 1.0]\n"), "line 8", "expected"),
        (format!("{CAMERA}{WHITE}albedo = \"red\"\n"), "line 6", "a number, an [r, g, b] array"),
        (format!("{CAMERA}aperture = true\n"), "line 6", "expected f32"),
    ];
    for (text, line, expected) in cases {
        assert_names(&parse_err(&text), &[line, "invalid", expected]);
    }
    let mesh = format!("{CAMERA}{WHITE}[[objects]]\ntype = \"mesh\"\nfile = \"a.obj\"\nmaterial = \"white\"\n");
    let msg = parse_err(&format!("{mesh}transform = {{ scale = \"big\" }}\n"));
    assert_names(&msg, &["line 8", "a number or an [x, y, z] array"]);
    let msg = parse_err(&format!("{mesh}transform = {{ scale = [1, 2] }}\n"));
    assert_names(&msg, &["line 8", "invalid length 2"]);
}

#[test]
fn resolution_must_be_a_positive_pixel_count() {
    let msg = parse_err(&CAMERA.replace("width = 8", "width = -5"));
    assert_names(&msg, &["line 4", "-5", "expected u32"]);
    let msg = parse_err(&CAMERA.replace("height = 8", "height = 2.5"));
    assert_names(&msg, &["line 5", "expected u32"]);
    let msg = parse_err(&CAMERA.replace("width = 8", "width = 0"));
    assert_names(&msg, &["camera.width", "1..=65536", "found 0"]);
    let msg = parse_err(&CAMERA.replace("height = 8", "height = 0"));
    assert_names(&msg, &["camera.height", "1..=65536"]);
    let msg = parse_err(&CAMERA.replace("height = 8", "height = 100000"));
    assert_names(&msg, &["camera.height", "found 100000"]);
}

/// A scene of the camera, the material `white` and one object of `fields` (its `type` and shape) in `white`.
fn object(fields: &str) -> String {
    format!("{CAMERA}{WHITE}[[objects]]\n{fields}material = \"white\"\n")
}

/// A scene of the camera and one point light of `fields`.
fn point_light(fields: &str) -> String {
    format!("{CAMERA}[[lights]]\ntype = \"point\"\n{fields}")
}

/// `nan`, `inf` and `-inf` are valid TOML floats: validation must catch each, wherever a number goes.
#[test]
fn nan_and_infinity_are_rejected_by_field() {
    let sphere = "type = \"sphere\"\ncenter = [0, 1, 0]\nradius = 0.5\n";
    let mesh = "type = \"mesh\"\nfile = \"a.obj\"\n";
    let cases = [
        (CAMERA.replace("eye = [0.0, 1.0, 3.0]", "eye = [X, 0, 0]"), "camera.eye"),
        (CAMERA.replace("look_at = [0.0, 1.0, 0.0]", "look_at = [0, X, 0]"), "camera.look_at"),
        (format!("{CAMERA}up = [0, 1, X]\n"), "camera.up"),
        (format!("{CAMERA}fov = X\n"), "camera.fov"),
        (format!("{CAMERA}aperture = X\n"), "camera.aperture"),
        (format!("{CAMERA}focus_distance = X\n"), "camera.focus_distance"),
        (format!("{CAMERA}[render]\nexposure = X\n"), "render.exposure"),
        (format!("{CAMERA}{WHITE}albedo = X\n"), "materials.white"),
        (object(&sphere.replace("radius = 0.5", "radius = X")), "objects[0].radius"),
        (object(&sphere.replace("center = [0, 1, 0]", "center = [0, 0, X]")), "objects[0].center"),
        (object(&format!("{sphere}emission = {{ radiance = [1, X, 1] }}\n")), "objects[0].emission.radiance"),
        (object(&format!("{mesh}transform = {{ translate = [0, X, 0] }}\n")), "objects[0].transform.translate"),
        (object(&format!("{mesh}transform = {{ rotate = [X, 0, 0] }}\n")), "objects[0].transform.rotate"),
        (object(&format!("{mesh}transform = {{ scale = X }}\n")), "objects[0].transform.scale"),
        (object("type = \"triangle\"\nvertices = [[0, 0, 0], [1, 0, 0], [0, X, 0]]\n"), "objects[0].vertices[2]"),
        (object("type = \"plane\"\npoint = [0, 0, 0]\nnormal = [0, X, 0]\n"), "objects[0].normal"),
        (object("type = \"rect\"\ncorner = [0, 0, 0]\nu = [1, 0, 0]\nv = [0, 0, X]\n"), "objects[0].v"),
        (point_light("position = [X, 1, 0]\npower = [1, 1, 1]\n"), "lights[0].position"),
        (point_light("position = [0, 1, 0]\nintensity = [1, X, 1]\n"), "lights[0].intensity"),
    ];
    for bad in ["nan", "inf", "-inf"] {
        for (text, field) in &cases {
            let msg = parse_err(&text.replace('X', bad));
            assert_names(&msg, &[field]);
            assert!(msg.contains("expected") || msg.contains("must"), "no expectation in: {msg}");
        }
    }
}

#[test]
fn out_of_range_values_name_the_field() {
    let sphere = "type = \"sphere\"\ncenter = [0, 1, 0]\nradius = 0.5\n";
    let phong = "[materials.p]\ntype = \"phong\"\ndiffuse = 0.8\nspecular = 0.5\n";
    let cases = [
        (object(&sphere.replace("radius = 0.5", "radius = -1")), "objects[0].radius", "positive"),
        (object(&sphere.replace("radius = 0.5", "radius = 0")), "objects[0].radius", "positive"),
        (object(&format!("{sphere}emission = {{ radiance = [1, -1, 1] }}\n")), "objects[0].emission", "non-negative"),
        (format!("{CAMERA}fov = 180\n"), "camera.fov", "(0, 180)"),
        (format!("{CAMERA}aperture = -0.1\n"), "camera.aperture", "non-negative"),
        (format!("{CAMERA}up = [0, 0, 0]\n"), "camera.up", "non-zero"),
        (format!("{CAMERA}up = [0, 0, 1]\n"), "camera.up", "parallel"),
        (CAMERA.replace("look_at = [0.0, 1.0, 0.0]", "look_at = [0.0, 1.0, 3.0]"), "camera.look_at", "differ"),
        (format!("{CAMERA}[render]\nspp = 0\n"), "render.spp", "at least 1"),
        (format!("{CAMERA}[render]\nmax_depth = 0\n"), "render.max_depth", "at least 1"),
        (format!("{CAMERA}{WHITE}albedo = 1.5\n"), "materials.white", "[0, 1]"),
        (format!("{CAMERA}[materials.glass]\ntype = \"dielectric\"\neta = 0\n"), "materials.glass", "eta"),
        (format!("{CAMERA}{phong}"), "materials.p", "exceeds 1"),
        (point_light("position = [0, 1, 0]\npower = [1, -1, 1]\n"), "lights[0].power", "non-negative"),
        (object("type = \"plane\"\npoint = [0, 0, 0]\nnormal = [0, 0, 0]\n"), "objects[0].normal", "non-zero"),
        (
            object("type = \"triangle\"\nvertices = [[0, 0, 0], [1, 1, 1], [2, 2, 2]]\n"),
            "objects[0].vertices",
            "no area",
        ),
        (
            object("type = \"mesh\"\nfile = \"a.obj\"\ntransform = { scale = [1, 0, 1] }\n"),
            "objects[0].transform.scale",
            "non-zero",
        ),
        (object("type = \"mesh\"\nfile = \"a.obj\"\ncrease_angle = 200\n"), "objects[0].crease_angle", "0 to 180"),
        (object("type = \"mesh\"\nfile = \"a.obj\"\ncrease_angle = -1\n"), "objects[0].crease_angle", "0 to 180"),
    ];
    for (text, field, expected) in cases {
        assert_names(&parse_err(&text), &[field, expected]);
    }
}

#[test]
fn missing_material_reference_lists_the_defined_ones() {
    let msg = parse_err(&format!("{CAMERA}{WHITE}{SPHERE}").replace("material = \"white\"", "material = \"red\""));
    assert_names(&msg, &["objects[0].material", "no material named `red`", "white"]);
}

#[test]
fn missing_required_fields_are_named() {
    let cases = [
        ("", "line 1", "missing field `camera`"),
        ("[render]\nspp = 4\n", "line 1", "missing field `camera`"),
        ("[camera]\nlook_at = [0, 1, 0]\n", "line 1", "missing field `eye`"),
        ("[camera]\neye = [0, 1, 3]\n", "line 1", "missing field `look_at`"),
    ];
    for (text, line, expected) in cases {
        assert_names(&parse_err(text), &[line, expected]);
    }
    for field in ["radius", "center", "material", "type"] {
        let sphere: String = SPHERE.lines().filter(|l| !l.starts_with(field)).map(|l| format!("{l}\n")).collect();
        let msg = parse_err(&format!("{CAMERA}{WHITE}{sphere}"));
        assert_names(&msg, &["line 8", &format!("missing field `{field}`")]);
    }
    let msg = parse_err(&format!("{CAMERA}[[lights]]\ntype = \"point\"\npower = [1, 1, 1]\n"));
    assert_names(&msg, &["line 6", "missing field `position`"]);
    let msg = parse_err(&format!("{CAMERA}{WHITE}{SPHERE}emission = {{ two_sided = true }}\n"));
    assert_names(&msg, &["line 8", "missing field `radiance`"]);
}

#[test]
fn rect_needs_exactly_one_complete_form() {
    let rect = format!("{CAMERA}{WHITE}[[objects]]\ntype = \"rect\"\nmaterial = \"white\"\n");
    let center = "center = [0, 1, 0]\nnormal = [0, 1, 0]\nwidth = 1\nheight = 1\n";
    let corner = "corner = [0, 0, 0]\nu = [1, 0, 0]\nv = [0, 0, 1]\n";
    let cases = [
        (format!("{rect}{center}{corner}"), "objects[0].corner", "not both"),
        (rect.clone(), "objects[0].center", "needs `center` (or `corner`)"),
        (format!("{rect}{center}").replace("normal = [0, 1, 0]\n", ""), "objects[0].normal", "needs `normal`"),
        (format!("{rect}{center}").replace("width = 1\n", ""), "objects[0].width", "needs `width`"),
        (format!("{rect}{center}").replace("width = 1", "width = -1"), "objects[0].width", "positive"),
        (format!("{rect}{center}tangent = [0, 2, 0]\n"), "objects[0].tangent", "parallel"),
        (format!("{rect}{center}v = [0, 0, 1]\n"), "objects[0].v", "go with `corner`"),
        (format!("{rect}{corner}width = 1\n"), "objects[0].corner", "use either"),
        (format!("{rect}{corner}").replace("u = [1, 0, 0]\n", ""), "objects[0].u", "needs edges"),
        (format!("{rect}{corner}").replace("v = [0, 0, 1]", "v = [2, 0, 0]"), "objects[0].v", "parallel"),
    ];
    for (text, field, expected) in cases {
        assert_names(&parse_err(&text), &[field, expected]);
    }
    // Both forms on their own are fine.
    Scene::parse(&format!("{rect}{center}"), Path::new(FILE)).unwrap();
    Scene::parse(&format!("{rect}{corner}"), Path::new(FILE)).unwrap();
}

#[test]
fn point_light_needs_exactly_one_of_intensity_and_power() {
    let light = format!("{CAMERA}[[lights]]\ntype = \"point\"\nposition = [0, 1, 0]\n");
    let msg = parse_err(&format!("{light}intensity = [1, 1, 1]\npower = [3, 3, 3]\n"));
    assert_names(&msg, &["lights[0].intensity", "exactly one of `intensity` and `power`"]);
    let msg = parse_err(&light);
    assert_names(&msg, &["lights[0].intensity", "exactly one of `intensity` and `power`"]);
    Scene::parse(&format!("{light}power = [3, 3, 3]\n"), Path::new(FILE)).unwrap();
}

#[test]
fn unreadable_scene_file_names_the_file() {
    let dir = temp_dir("unreadable");
    let path = dir.join("no-such-scene.toml");
    let e = Scene::load(&path).unwrap_err();
    let msg = chain(&e);
    let _ = std::fs::remove_dir_all(&dir);
    assert!(msg.contains("no-such-scene.toml") && msg.contains("cannot read the scene file"), "{msg}");
}

#[test]
fn missing_mesh_file_names_the_scene_the_field_and_the_mesh() {
    let msg = mesh_err("missing-mesh", "missing.obj", None);
    assert!(msg.contains("missing.obj") && msg.contains("cannot read the mesh"), "{msg}");
    // The cause is told once, not once per link of the error chain.
    assert_eq!(msg.matches("cannot read the mesh").count(), 1, "{msg}");
}

#[test]
fn malformed_obj_vertex_gives_file_and_line() {
    let msg = mesh_err("bad-vertex", "bad.obj", Some("v 0 0 0\nv 1 0 0\nv 1 zz 0\nf 1 2 3\n"));
    assert!(msg.contains("bad.obj:3"), "{msg}");
    assert_eq!(msg.matches("bad.obj:3").count(), 1, "{msg}");
    let msg = mesh_err("short-vertex", "short.obj", Some("v 0 0 0\nv 1 0\nv 1 1 0\nf 1 2 3\n"));
    assert!(msg.contains("short.obj:2"), "{msg}");
    let msg = mesh_err("nan-vertex", "nan.obj", Some("v 0 0 0\nv 1 nan 0\nv 1 1 0\nf 1 2 3\n"));
    assert!(msg.contains("nan.obj:2") && msg.contains("not finite"), "{msg}");
}

#[test]
fn obj_face_index_out_of_range_gives_file_and_line() {
    let msg = mesh_err("face-oob", "oob.obj", Some("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 4\n"));
    assert!(msg.contains("oob.obj:4") && msg.contains("out of bounds"), "{msg}");
    let msg = mesh_err("face-negative-oob", "neg.obj", Some("v 0 0 0\nv 1 0 0\nv 1 1 0\nf -1 -2 -5\n"));
    assert!(msg.contains("neg.obj:4"), "{msg}");
    let msg = mesh_err("face-zero", "zero.obj", Some("v 0 0 0\nv 1 0 0\nv 1 1 0\n\nf 0 1 2\n"));
    assert!(msg.contains("zero.obj:5"), "{msg}");
    let uv = "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/2 3/3\n";
    let msg = mesh_err("texcoord-oob", "uv.obj", Some(uv));
    assert!(msg.contains("uv.obj:5") && msg.contains("texcoord"), "{msg}");
}

#[test]
fn empty_obj_is_an_error() {
    let msg = mesh_err("empty-obj", "empty.obj", Some(""));
    assert!(msg.contains("empty.obj") && msg.contains("no faces"), "{msg}");
    let msg = mesh_err("points-only", "points.obj", Some("# only vertices\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"));
    assert!(msg.contains("points.obj") && msg.contains("no faces"), "{msg}");
}

/// Every truncation of a real scene, and every scene with one line removed, parses or fails cleanly; those that
/// parse also prepare.
#[test]
fn damaged_scenes_never_panic() {
    let path = scenes_dir().join("cornell.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut variants: Vec<String> =
        (0..text.len()).filter(|&i| text.is_char_boundary(i)).map(|i| text[..i].into()).collect();
    variants.extend(
        (0..lines.len())
            .map(|skip| lines.iter().enumerate().filter(|&(i, _)| i != skip).map(|(_, l)| format!("{l}\n")).collect()),
    );
    let mut failed = 0;
    for v in &variants {
        match Scene::parse(v, &path) {
            Ok(scene) => {
                Prepared::new(&scene, &path).unwrap().with_photon_maps(&path).unwrap();
            }
            Err(e) => {
                assert!(e.to_string().contains("cornell.toml"), "{e}");
                failed += 1;
            }
        }
    }
    assert!(failed > 0 && failed < variants.len(), "{failed} of {} variants failed", variants.len());
}

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("scenes")
}

#[test]
fn shipped_scenes_load_and_prepare() {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(scenes_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let prep = Prepared::load(&path).unwrap_or_else(|e| panic!("{e}"));
            assert!(prep.geometry.prim_count() > 0, "{}", path.display());
            assert!(!prep.lights.lights.is_empty(), "{}", path.display());
            names.push(path.file_name().unwrap().to_string_lossy().into_owned());
        }
    }
    for expected in ["cornell.toml", "cornell-point.toml", "mesh.toml"] {
        assert!(names.iter().any(|n| n == expected), "{expected} not found among {names:?}");
    }
}

/// Every ```toml block of docs/SCENE.md is a valid scene once the camera and the material `white` it may take
/// for granted are added; it is prepared with paths resolved against `scenes/`, where the manual's meshes live.
#[test]
fn manual_examples_parse_and_prepare() {
    let manual = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/SCENE.md");
    let text = std::fs::read_to_string(&manual).unwrap();
    let mut blocks = Vec::new();
    let mut current: Option<(usize, String)> = None;
    for (i, line) in text.lines().enumerate() {
        let fence = line.trim_start().starts_with("```");
        match current.take() {
            None if line.trim_start().starts_with("```toml") => current = Some((i + 1, String::new())),
            None => {}
            Some(block) if fence => blocks.push(block),
            Some((start, mut block)) => {
                block.push_str(line);
                block.push('\n');
                current = Some((start, block));
            }
        }
    }
    assert!(blocks.len() >= 10, "only {} toml examples found in the manual", blocks.len());
    let path = scenes_dir().join("manual-example.toml");
    for (line, block) in blocks {
        let mut scene = String::new();
        if !block.contains("[camera]") {
            scene.push_str(CAMERA);
        }
        if !block.contains("[materials.white]") {
            scene.push_str(WHITE);
        }
        scene.push_str(&block);
        let parsed = Scene::parse(&scene, &path).unwrap_or_else(|e| panic!("SCENE.md:{line}: {e}"));
        Prepared::new(&parsed, &path).unwrap_or_else(|e| panic!("SCENE.md:{line}: {}", chain(&e)));
    }
}

/// The manual's order of a mesh transform: scale, then rotate about x, y and z (world axes), then translate.
#[test]
fn manual_transform_order_holds() {
    use photon_core::scene::{Scale, Transform};
    let t = Transform {
        translate: glam::Vec3::new(10.0, 0.0, 0.0),
        rotate: glam::Vec3::new(90.0, 90.0, 0.0),
        scale: Scale::PerAxis(glam::Vec3::new(1.0, 2.0, 1.0)),
    };
    // y scaled to 2y; about x, y goes to z; about y, z goes to x; then moved by 10 along x.
    let p = t.matrix().transform_point3(glam::Vec3::Y);
    assert!((p - glam::Vec3::new(12.0, 0.0, 0.0)).length() < 1e-5, "{p}");
}

/// A value the types accept but validation refuses is reported at the line of its key.
#[test]
fn validation_errors_give_the_line_of_the_field() {
    let text = format!(
        "{CAMERA}{WHITE}[[objects]]\ntype = \"sphere\"\ncenter = [0.0, 1.0, 0.0]\nradius = -0.5\nmaterial = \"white\"\n"
    );
    let line = text.lines().position(|l| l.starts_with("radius")).unwrap() + 1;
    let msg = parse_err(&text);
    assert_names(&msg, &[&format!("{FILE}:{line}:"), "objects[0].radius", "expected a positive number"]);
    // A field left at its default that is refused points at its table: `[render]` here.
    let msg = parse_err(&format!("{CAMERA}{WHITE}[render]\nspp = 0\n"));
    assert_names(&msg, &[&format!("{FILE}:{}:", CAMERA.lines().count() + 4), "render.spp"]);
}

/// `--set` pairs (and the command line's shorthands, which are `--set` pairs) are errors that name the scene
/// field and the override, whether the value has the wrong type or is refused by validation.
#[test]
fn override_errors_name_the_scene_field() {
    let dir = temp_dir("overrides");
    let path = dir.join(FILE);
    std::fs::write(&path, format!("{CAMERA}{WHITE}{SPHERE}")).unwrap();
    let load = |sets: &[&str]| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        Scene::load_with(&path, &sets).map(|_| ()).map_err(|e| chain(&e))
    };
    let msg = load(&["render.spp=4", "render.photons.k=-1"]).unwrap_err();
    assert_names(&msg, &["render.photons.k:", "--set render.photons.k=-1", "u32"]);
    let msg = load(&["render.photons.k=1"]).unwrap_err();
    assert_names(&msg, &["render.photons.k:", "expected 2 to 100000 photons", "--set render.photons.k=1"]);
    let msg = load(&["camera.width=0"]).unwrap_err();
    assert_names(&msg, &["camera.width:", "1..=65536", "--set camera.width=0"]);
    let msg = load(&["render.spp"]).unwrap_err();
    assert_names(&msg, &["expected KEY=VALUE"]);
    assert!(load(&["render.spp=3", "render.photons.kernel=box"]).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn camera_coordinates_that_would_overflow_name_their_own_field() {
    // |look_at − eye|² overflows f32 here: once blamed on `camera.up`.
    let text = "[camera]\neye = [0.0, 1.0, 3.0e38]\nlook_at = [0.0, 1.0, 0.0]\n";
    assert_names(&parse_err(text), &[":2:", "camera.eye:", "within ±1e18"]);
    let text = "[camera]\neye = [0.0, 1.0, 3.0]\nlook_at = [0.0, 1.0, 0.0]\nup = [0.0, 1.0e30, 0.0]\n";
    assert_names(&parse_err(text), &["camera.up:", "within ±1e18"]);
}

#[test]
fn spot_directional_and_environment_lights_name_the_field_that_is_wrong() {
    let light = |body: &str| format!("{CAMERA}{WHITE}{SPHERE}[[lights]]\n{body}");
    let spot = "type = \"spot\"\nposition = [0, 2, 0]\ndirection = [0, -1, 0]\nintensity = [1, 1, 1]\n";
    let env = "type = \"environment\"\nradiance = [1, 1, 1]\n";
    let cases = [
        (light(&spot.replace("direction = [0, -1, 0]", "direction = [0, 0, 0]")), "lights[0].direction", "non-zero"),
        (light(&format!("{spot}outer_angle = 95\n")), "lights[0].outer_angle", "(0, 90]"),
        (light(&format!("{spot}outer_angle = 0\n")), "lights[0].outer_angle", "(0, 90]"),
        (light(&format!("{spot}inner_angle = 50\n")), "lights[0].inner_angle", "[0, outer_angle = 45]"),
        (light(&spot.replace("intensity = [1, 1, 1]\n", "")), "lights[0].intensity", "exactly one"),
        (
            light("type = \"directional\"\ndirection = [0, -1, 0]\nirradiance = [1, -1, 1]\n"),
            "lights[0].irradiance",
            "non-negative",
        ),
        (
            light("type = \"directional\"\ndirection = [0, 0, 0]\nirradiance = [1, 1, 1]\n"),
            "lights[0].direction",
            "non-zero",
        ),
        (light("type = \"environment\"\n"), "lights[0].radiance", "exactly one of `radiance` and `image`"),
        (light(&format!("{env}image = \"sky.exr\"\n")), "lights[0].radiance", "exactly one of `radiance` and `image`"),
        (light(&format!("{env}scale = 2.0\n")), "lights[0].scale", "with `image`"),
        (light("type = \"environment\"\nimage = \"sky.exr\"\nscale = -1.0\n"), "lights[0].scale", "≥ 0"),
        (format!("{}[[lights]]\n{env}", light(env)), "lights[1].type", "at most one environment"),
        (format!("{}[medium]\ndensity = 0.1\n", light(env)), "lights[0].type", "participating media"),
    ];
    for (text, field, expected) in cases {
        assert_names(&parse_err(&text), &[field, expected]);
    }
    Scene::parse(&light(spot), Path::new(FILE)).unwrap();
    Scene::parse(&light(env), Path::new(FILE)).unwrap();
}

#[test]
fn a_missing_or_broken_environment_image_names_the_light_and_the_file() {
    let dir = temp_dir("environment-image");
    std::fs::write(dir.join("broken.exr"), b"not an image").unwrap();
    for file in ["missing.hdr", "broken.exr"] {
        let text = format!("{CAMERA}{WHITE}{SPHERE}[[lights]]\ntype = \"environment\"\nimage = \"{file}\"\n");
        let path = dir.join(FILE);
        let scene = Scene::parse(&text, &path).unwrap();
        let msg = match Prepared::new(&scene, &path) {
            Ok(_) => panic!("prepared a scene whose environment image is {file}"),
            Err(e) => chain(&e),
        };
        assert_names(&msg, &["lights[0]", file]);
    }
}

"""photon against Blender's Cycles on the same simple scenes: a diffuse, a rough metal and a rough glass sphere on a
diffuse floor under a constant environment, and the diffuse sphere under scenes/textures/sky.hdr.

Run by docs/figures/cycles/run.sh inside Blender (`blender -b --factory-startup -P compare.py -- OUT_DIR PHOTON`),
never by CI: Cycles is a benchmark peer, not a dependency. For each case it writes photon's scene, renders it
with photon's path tracer, builds the same scene in Cycles (Blender is z-up: photon's (x, y, z) is Blender's
(x, -z, y)), renders it, reads both linear EXR images and prints the mean of each channel and their ratio, as a
Markdown table.

The material models, and where they differ:
- diffuse: photon's `lambert` and Cycles' Diffuse BSDF (roughness 0) are the same Lambert lobe;
- rough metal: photon's `conductor` with `color` (Schlick's F0, glTF's metal) and Cycles' Principled BSDF with
  metallic 1 and that base colour, both single-scattering GGX with alpha = roughness^2 (Principled's
  distribution set to 'GGX', not multiscatter), with Fresnel by Schlick on both;
- rough glass: photon's `dielectric` with `roughness` and Cycles' Glass BSDF ('GGX'), both Walter et al. 2007.
"""

import subprocess
import sys
from pathlib import Path

import bpy
import mathutils

REPO = Path(__file__).resolve().parents[3]
SIZE = 128
SPP = 256

FLOOR = 0.5
CASES = {
    "diffuse": {"type": "lambert", "albedo": 0.8},
    "rough-metal": {"type": "conductor", "color": [0.95, 0.64, 0.54], "roughness": 0.4},
    "rough-glass": {"type": "dielectric", "eta": 1.5, "roughness": 0.2},
    "diffuse-sky": {"type": "lambert", "albedo": 0.8, "sky": True},
}


def toml_value(v):
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(str(x) for x in v) + "]"
    return str(v)


def photon_scene(material, sky):
    m = "\n".join(f"{k} = {toml_value(v)}" for k, v in material.items() if k != "sky")
    light = f'image = "{REPO / "scenes/textures/sky.hdr"}"' if sky else "radiance = [1.0, 1.0, 1.0]"
    return f"""
[camera]
eye = [0.0, 1.0, 3.0]
look_at = [0.0, 0.5, 0.0]
fov = 40.0
width = {SIZE}
height = {SIZE}

[render]
spp = {SPP}
max_depth = 16
integrator = "path"

[materials.floor]
type = "lambert"
albedo = {FLOOR}

[materials.ball]
{m}

[[objects]]
type = "rect"
center = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
width = 10.0
height = 10.0
material = "floor"

[[objects]]
type = "sphere"
center = [0.0, 0.5, 0.0]
radius = 0.5
material = "ball"

[[lights]]
type = "environment"
{light}
"""


def blender_vector(p):
    x, y, z = p
    return mathutils.Vector((x, -z, y))


def blender_sky():
    """scenes/textures/sky.hdr in Cycles' equirectangular layout. Cycles' column u looks along azimuth
    pi*(1 - 2u) from its -x towards +y, photon's along pi*(2u - 1) from its -z (Blender's +y) towards +x; the
    rows agree (polar angle from the zenith). So Cycles' column u is photon's column 3/4 - u (mod 1): for a
    width divisible by 4, texel column i is photon's column (3w/4 - 1 - i) mod w, an exact permutation."""
    ours = bpy.data.images.load(str(REPO / "scenes/textures/sky.hdr"))
    w, h = ours.size
    px = list(ours.pixels)
    out = [0.0] * len(px)
    for j in range(h):
        for i in range(w):
            src = (j * w + (3 * w // 4 - 1 - i) % w) * 4
            out[(j * w + i) * 4 : (j * w + i) * 4 + 4] = px[src : src + 4]
    img = bpy.data.images.new("sky-cycles", w, h, float_buffer=True)
    img.pixels = out
    return img


def cycles_scene(material, sky):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = SPP
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    for bounces in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces"):
        setattr(scene.cycles, bounces, 16)
    scene.cycles.transparent_max_bounces = 16
    scene.cycles.sample_clamp_direct = 0.0
    scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.blur_glossy = 0.0
    scene.cycles.caustics_reflective = True
    scene.cycles.caustics_refractive = True
    scene.render.resolution_x = SIZE
    scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"

    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    nodes = world.node_tree.nodes
    background = nodes["Background"]
    background.inputs["Strength"].default_value = 1.0
    if sky:
        tex = nodes.new("ShaderNodeTexEnvironment")
        tex.image = blender_sky()
        tex.interpolation = "Closest"
        world.node_tree.links.new(tex.outputs["Color"], background.inputs["Color"])
    else:
        background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)

    cam = bpy.data.cameras.new("camera")
    cam.sensor_fit = "VERTICAL"
    cam.angle_y = 40.0 * 3.141592653589793 / 180.0
    cam_obj = bpy.data.objects.new("camera", cam)
    scene.collection.objects.link(cam_obj)
    eye, target = blender_vector((0.0, 1.0, 3.0)), blender_vector((0.0, 0.5, 0.0))
    cam_obj.location = eye
    cam_obj.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam_obj

    def surface(name, bsdf_setup):
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        tree = mat.node_tree
        tree.nodes.clear()
        out = tree.nodes.new("ShaderNodeOutputMaterial")
        bsdf = bsdf_setup(tree)
        tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
        return mat

    def diffuse(albedo):
        def setup(tree):
            n = tree.nodes.new("ShaderNodeBsdfDiffuse")
            n.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
            n.inputs["Roughness"].default_value = 0.0
            return n

        return setup

    def ball_setup(tree):
        kind = material["type"]
        if kind == "lambert":
            return diffuse(material["albedo"])(tree)
        if kind == "conductor":
            n = tree.nodes.new("ShaderNodeBsdfPrincipled")
            n.distribution = "GGX"
            n.inputs["Base Color"].default_value = (*material["color"], 1.0)
            n.inputs["Metallic"].default_value = 1.0
            n.inputs["Roughness"].default_value = material["roughness"]
            return n
        n = tree.nodes.new("ShaderNodeBsdfGlass")
        n.distribution = "GGX"
        n.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        n.inputs["Roughness"].default_value = material["roughness"]
        n.inputs["IOR"].default_value = material["eta"]
        return n

    bpy.ops.mesh.primitive_plane_add(size=10.0, location=(0.0, 0.0, 0.0))
    bpy.context.active_object.data.materials.append(surface("floor", diffuse(FLOOR)))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=0.5, location=blender_vector((0, 0.5, 0)))
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(surface("ball", ball_setup))


def mean(path):
    img = bpy.data.images.load(str(path))
    px = list(img.pixels)
    n = len(px) // 4
    return [sum(px[c::4]) / n for c in range(3)]


def main():
    args = sys.argv[sys.argv.index("--") + 1 :]
    out, photon = Path(args[0]), args[1]
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, material in CASES.items():
        sky = material.get("sky", False)
        toml = out / f"{name}.toml"
        toml.write_text(photon_scene(material, sky))
        ours = out / f"{name}-photon.exr"
        subprocess.run([photon, "render", str(toml), "-o", str(ours), "-q", "--no-cache"], check=True)
        cycles_scene(material, sky)
        theirs = out / f"{name}-cycles.exr"
        bpy.context.scene.render.filepath = str(theirs)
        bpy.ops.render.render(write_still=True)
        a, b = mean(ours), mean(theirs)
        rows.append((name, a, b))
    print("| case | photon mean (r, g, b) | Cycles mean (r, g, b) | photon / Cycles |")
    print("|---|---|---|---|")
    for name, a, b in rows:
        fmt = lambda v: ", ".join(f"{x:.4f}" for x in v)  # noqa: E731
        ratio = ", ".join(f"{x / y:.4f}" if y > 0 else "-" for x, y in zip(a, b))
        print(f"| {name} | {fmt(a)} | {fmt(b)} | {ratio} |")


main()

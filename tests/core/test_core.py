"""core/: field compositing, metrics, bake planning, atomic files, VDB and image I/O (no Blender)."""

from pathlib import Path

import numpy as np
import pytest

from nubis_addon.core import fields, imageio, metrics, vdbwrite
from nubis_addon.core.bakeplan import plan_bake
from nubis_addon.core.errors import NubisError
from nubis_addon.core.fsutil import atomic_path, check_output_path
from nubis_addon.core.presets import load_preset
from nubis_addon.core.schema import defaults
from nubis_addon.core.state import CloudState


def small_params(**kw):
    p = defaults()
    p.update(field_resolution=64, **kw)
    return p


def test_composite_default_preset_is_in_range_and_deterministic():
    preset = load_preset("default")
    params = dict(preset.params, field_resolution=64)
    a = fields.composite(preset.layers, params)
    b = fields.composite(preset.layers, params)
    for key in ("a", "b", "cirrus"):
        assert a[key].shape == (64, 64, 4) and a[key].dtype == np.float32
        np.testing.assert_array_equal(a[key], b[key])
    assert 0.0 <= a["a"].min() and a["a"].max() <= 1.0
    assert a["a"][..., 0].std() > 0.05  # coverage varies across the sky


def _layer(**kw):
    from nubis_addon.core import schema

    layer = schema.table_defaults(schema.FIELD_LAYER)
    layer.update(kw)
    return layer


@pytest.mark.parametrize(
    ("mode", "expected"), [("replace", 0.8), ("add", 1.0), ("multiply", 0.4), ("min", 0.5), ("max", 0.8)]
)
def test_blend_modes(mode, expected):
    layers = [
        _layer(name="base", kind="constant", value=0.5),
        _layer(name="top", kind="constant", value=0.8, blend=mode),
    ]
    out = fields.composite(layers, small_params())
    assert out["a"][..., 0] == pytest.approx(expected)


def test_opacity_mask_and_remap():
    layers = [
        _layer(name="left", kind="gradient", angle=0.0, radius=35000.0, channel="none"),
        _layer(name="cov", kind="constant", value=1.0, mask="left", opacity=0.5, remap=[0.0, 1.0, 0.0, 0.8]),
    ]
    cov = fields.composite(layers, small_params())["a"][..., 0]
    assert cov[:, 0].max() < 0.02  # mask ~0 on the -X side
    assert cov[:, -1].min() == pytest.approx(0.4, abs=0.02)  # 0.8 remapped x opacity 0.5 x mask ~1


def test_image_layer_errors_are_clear():
    with pytest.raises(NubisError, match="uses the image 'paint', which is missing"):
        fields.composite([_layer(kind="image", image="paint")], small_params())
    bad = np.full((8, 8), np.nan, np.float32)
    with pytest.raises(NubisError, match="NaN"):
        fields.composite([_layer(kind="image", image="paint")], small_params(), {"paint": bad})


def test_rain_and_horizon_rules():
    f = fields.base_fields(64)
    f["a"][..., 1] = 1.0  # 100 % chance of rain everywhere
    fields.apply_rain_rule(f, cumulonimbus_top=2.6)
    assert f["a"][..., 0].min() >= 0.7 - 1e-6 and f["a"][..., 2].min() == pytest.approx(1.0)
    assert f["b"][..., 2].min() == pytest.approx(2.6)
    g = fields.base_fields(64)
    p = small_params()
    fields.apply_horizon_rule(g, p, (0.0, 0.0))
    assert g["a"][32, 32, 0] == pytest.approx(0.0)  # near the centre nothing changes
    assert g["a"][0, 0, 2] == pytest.approx(1.0)  # the far corner turns to cumulus at ~50 %
    assert g["a"][0, 0, 0] == pytest.approx(0.5)


def test_metrics_identical_and_shifted():
    rng = np.random.default_rng(1)
    a = rng.random((16, 16, 4)).astype(np.float32)
    m = metrics.compare(a, a)
    assert m["alpha_rmse"] == 0 and m["luminance_rel_error"] == 0 and m["silhouette_iou"] == 1
    b = a.copy()
    b[..., :3] *= 1.1
    assert metrics.compare(a, b)["luminance_rel_error"] == pytest.approx(0.1 / 1.1, rel=1e-4)


def test_bake_plan_covers_the_draw_radius_and_refuses_absurd_sizes():
    state = CloudState()
    plan = plan_bake(state, 500.0)
    nx, ny, nz = plan.dims
    assert nx * 500 >= 70000 and ny * 500 >= 70000
    z0 = plan.origin[2] - 250  # origin is the first voxel's centre
    assert z0 < state.params["layer_bottom"] and z0 + nz * 500 >= state.params["layer_top"]
    with pytest.raises(NubisError, match="use a voxel size of at least"):
        plan_bake(state, 1.0)
    with pytest.raises(NubisError, match="positive"):
        plan_bake(state, float("nan"))


def test_atomic_write_keeps_the_old_file_on_failure(tmp_path: Path):
    target = tmp_path / "keep.txt"
    target.write_text("good")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("crash mid-write")
    assert target.read_text() == "good"
    assert list(tmp_path.iterdir()) == [target]


def test_output_path_checks(tmp_path: Path):
    with pytest.raises(NubisError, match="use one of the extensions"):
        check_output_path(tmp_path / "x.jpg", (".png", ".exr"))
    with pytest.raises(NubisError, match="cannot create the folder|cannot write into"):
        check_output_path("/proc/nubis/x.png", (".png",))
    assert check_output_path(tmp_path / "new" / "x.png", (".png",)).parent.is_dir()


def test_vdb_round_trip(tmp_path: Path):
    vol = np.zeros((4, 5, 6), np.float32)  # z, y, x
    vol[1, 2, 3] = 0.75
    path = vdbwrite.write_vdb(tmp_path / "t.vdb", {"density": vol}, 50.0, (100.0, 200.0, 1500.0))
    info = vdbwrite.read_grid_info(path)["density"]
    assert info.active_voxels == 1 and info.voxel_size == pytest.approx(50.0)
    assert info.origin == pytest.approx((100.0, 200.0, 1500.0))
    assert info.index_bbox == ((3, 2, 1), (3, 2, 1))  # x, y, z
    with pytest.raises(NubisError, match="NaN"):
        vdbwrite.write_vdb(tmp_path / "t.vdb", {"density": vol * np.nan}, 50.0, (0, 0, 0))
    assert vdbwrite.read_grid_info(path)["density"].active_voxels == 1  # the good file survived


def test_image_round_trip(tmp_path: Path):
    px = np.zeros((6, 8, 4), np.float32)
    px[0, 0] = (2.5, 0.5, 0.25, 0.5)
    imageio.write_image(tmp_path / "a.exr", px)
    back = imageio.read_image(tmp_path / "a.exr")
    np.testing.assert_allclose(back, px, atol=1e-3)
    imageio.write_image(tmp_path / "a.png", np.clip(px, 0, 1))
    assert imageio.read_image(tmp_path / "a.png").shape == (6, 8, 4)
    with pytest.raises(NubisError, match="NaN"):
        imageio.write_image(tmp_path / "b.exr", px * np.nan)
    assert not (tmp_path / "b.exr").exists()


def test_uniform_block_matches_the_glsl_struct():
    from nubis_addon.core.state import StormLight
    from nubis_addon.render import uniforms

    members = uniforms.struct_members()
    floats = sum(4 * (n or 1) if typ == "vec4" else 1 for _name, typ, n in members)
    state = CloudState(storms=(StormLight(1.0, 2.0, 3000.0),))
    data = uniforms.pack(state)
    assert floats % 4 == 0 and data.shape == (floats // 4, 4) and data.dtype == np.float32
    # std140: vec4 members and arrays start on whole rows; the floats between them fill rows densely.
    offsets, at = {}, 0
    for name, typ, n in members:
        if typ == "vec4":
            assert at % 4 == 0, name
        offsets[name] = at
        at += 4 * (n or 1) if typ == "vec4" else 1
    flat = data.ravel()
    start = offsets["storm_shape"]
    assert tuple(flat[start : start + 4]) == (1.0, 2.0, 3000.0, 1.0)  # first storm, then zero padding
    assert not flat[start + 4 : start + 8].any()
    assert flat[offsets["lighting_powder"]] == np.float32(state.params["lighting_powder"])
    assert flat[offsets["layer_bottom"]] == np.float32(state.params["layer_bottom"])
    src = uniforms.struct_source()
    assert "float lighting_powder;" in src and "vec4 storm_shape[NUBIS_MAX_STORMS];" in src
    bad = CloudState()
    bad.params = dict(bad.params, density_sigma=float("nan"))
    with pytest.raises(NubisError, match="non-finite"):
        uniforms.pack(bad)


def test_view_rays_keep_their_direction_through_a_deep_frustum():
    """A 0.1 m - 200 km sky camera: rays from the conditioned float64 inverse match the pinhole
    camera's exact directions, even after rounding the matrix and the arithmetic to float32 as the
    GPU does (mathutils' float32 inversion of the real projection turned them by 0.3 degrees)."""
    from nubis_addon.core.camera import ray_inverse_view_projection

    n, f, half_w, half_h = 0.1, 200000.0, 0.5, 0.28125  # 18 mm lens on a 36 mm sensor, 16:9
    proj = np.array(
        [
            [1 / half_w, 0, 0, 0],
            [0, 1 / half_h, 0, 0],
            [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)],
            [0, 0, -1, 0],
        ]
    )
    angle = np.radians(150.0)
    rot = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    cam = np.eye(4)
    cam[:3, :3], cam[:3, 3] = rot, (0.0, -6000.0, 2.0)
    view = np.linalg.inv(cam)
    ndc = np.array([[0.0, 0.0], [0.9, 0.9], [-0.9, 0.5]])
    exact = (np.c_[ndc[:, 0] * half_w, ndc[:, 1] * half_h, -np.ones(len(ndc))]) @ rot.T
    exact /= np.linalg.norm(exact, axis=1, keepdims=True)

    def directions(inv):
        h = np.c_[ndc, np.ones(len(ndc)), np.ones(len(ndc))] @ np.asarray(inv, np.float32).T.astype(np.float32)
        d = h[:, :3] / h[:, 3:] - cam[:3, 3].astype(np.float32)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def angle_deg(a):
        return np.degrees(np.arccos(np.clip(np.sum(a * exact, axis=1), -1, 1))).max()

    pixel_deg = np.degrees(2 * np.arctan(half_w)) / 48
    assert angle_deg(directions(ray_inverse_view_projection(proj, view))) < 0.01 * pixel_deg


def test_not_a_file_says_what_the_path_is(tmp_path):
    """A .blend or image-layer path that is a folder or a device is named as such, not as missing."""
    from nubis_addon.core.fsutil import not_a_file

    (tmp_path / "real.png").write_bytes(b"x")
    assert not_a_file(tmp_path / "real.png") == ""
    assert not_a_file(tmp_path / "missing.png") == "does not exist"
    assert not_a_file(tmp_path) == "is a folder, not a file"
    assert not_a_file(Path("/dev/zero")) == "is a device or special file, not a regular file"
    assert not_a_file(tmp_path / ("n" * 300 + ".png")) == "has a name longer than the file system allows"


def test_no_temporary_folder_is_made_once_an_interrupt_cleans_up(tmp_path, monkeypatch):
    """The watcher of an interrupt snapshots the registered paths and ends the process; the main thread
    runs on meanwhile. A folder made after the snapshot was left behind (seen once in CI: a nubis-cycles-
    folder after SIGTERM). Making and registering now wait for a cleaning-up watcher, which never returns."""
    import tempfile
    import threading
    import time

    from nubis_addon.core import interrupt

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    made = []

    def main_thread_work():
        with interrupt.temporary_dir("nubis-race-") as tmp:
            made.append(tmp)

    interrupt._lock.acquire()  # what _die holds from before its snapshot until os._exit
    try:
        worker = threading.Thread(target=main_thread_work, daemon=True)
        worker.start()
        time.sleep(0.3)
        assert worker.is_alive() and not made and not list(tmp_path.iterdir())
    finally:
        interrupt._lock.release()
    worker.join(5)
    assert made and not list(tmp_path.iterdir())  # made, registered, used and removed once allowed


# ---- the optical-depth volumes (core/lightvolume.py) ----------------------------------------------------


def test_light_volume_boxes_hold_the_cloud_domain_and_face_the_light():
    from nubis_addon.core import lightvolume
    from nubis_addon.core.state import CloudState

    state = CloudState(draw_center=(1200.0, -800.0))
    radius = state.params["layer_draw_radius"]
    bottom, top = state.shell()
    for sun in ((0.3, -0.5, 0.81), (0.0, 0.0, 1.0), (0.99, 0.0, 0.05), (-0.2, 0.1, -0.3)):
        box = lightvolume.volume(sun, state)
        rows = box.to_unit()
        # Every corner of the domain (the draw radius' square, between the shell's floor and top) is inside.
        centre, half, low, high = lightvolume.domain(state)
        assert low < bottom and high == top and half[0] >= radius
        for x in (-1, 1):
            for y in (-1, 1):
                for z in (low, high):
                    p = np.array([centre[0] + x * half[0], centre[1] + y * half[1], z])
                    unit = rows[:, :3] @ p + rows[:, 3]
                    assert np.all(unit > -1e-6) and np.all(unit < 1 + 1e-6), (sun, unit)
        # The unit map inverts the box's own parametrisation, and z grows away from the light.
        for unit in ((0.0, 0.0, 0.0), (0.25, 0.5, 1.0), (1.0, 1.0, 0.5)):
            p = box.point(unit)
            assert np.allclose(rows[:, :3] @ p + rows[:, 3], unit, atol=1e-9)
        s = np.asarray(sun) / np.linalg.norm(sun)
        assert np.dot(box.point((0.5, 0.5, 1.0)) - box.point((0.5, 0.5, 0.0)), s) < 0
    # A small camera move keeps the box (the volumes are not refilled), a large one moves it.
    moved = CloudState(draw_center=(1200.0 + 0.02 * radius, -800.0))
    far = CloudState(draw_center=(1200.0 + 0.5 * radius, -800.0))
    assert lightvolume.key_centre(moved) == lightvolume.key_centre(state) != lightvolume.key_centre(far)
    # ... and the map the shaders read is the one the volumes were filled with.
    sun = (0.3, -0.5, 0.81)
    assert np.array_equal(lightvolume.volume(sun, moved).to_unit(), lightvolume.volume(sun, state).to_unit())
    # A comparison's box replaces the draw radius: finer texels over the baked clouds.
    state.clip_box = (-500.0, -400.0, 1500.0, 600.0)
    centre, half, _low, _high = lightvolume.domain(state)
    assert centre == (500.0, 100.0) and half == (1000.0, 500.0)
    # The sun's volume and the sky's two channels: 12 MB, with the noise set's 10.3 MiB a little over GPU Pro 7's
    # 20 MB (docs/viewport.md#light-volumes says why).
    assert lightvolume.memory_bytes() == 12 * 2**20


def test_light_volumes_follow_the_wind_in_steps_of_the_refill_drift():
    from nubis_addon.core import lightvolume
    from nubis_addon.core.state import CloudState

    state = CloudState()
    p = state.params
    speed = p["wind_speed"] * max(1.0, p["wind_detail_speed"])
    texel = 2 * max(lightvolume.domain(state)[1]) / lightvolume.SIZE[0]
    step = lightvolume.REFILL_DRIFT * texel / speed
    at = [lightvolume.refill_time(CloudState(time=t)) for t in (0.0, 0.9 * step, 1.1 * step, 10.5 * step)]
    assert at == pytest.approx([0.0, 0.0, step, 10 * step])
    still = CloudState(time=1234.5)
    still.params["wind_speed"] = 0.0
    assert lightvolume.refill_time(still) == 0.0
    assert lightvolume.lighting_only("lighting_ambient") and not lightvolume.lighting_only("lighting_rain_absorption")
    assert not lightvolume.lighting_only("density_sigma")


def test_a_sun_above_the_horizon_gets_a_volume_sliced_by_altitude():
    """Its depth slices are altitudes whatever the sun's elevation: a stratus deck under a 30 degree sun
    gets its 32 slices over the layer's height, not over the domain's 70 km seen along the sun."""
    from nubis_addon.core import lightvolume
    from nubis_addon.core.state import CloudState

    state = CloudState()
    _centre, _half, bottom, top = lightvolume.domain(state)
    sun = np.array([0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
    box = lightvolume.volume(sun, state)
    rows = box.to_unit()
    # Every texel of one slice has the same altitude, and the slices run from the top to the floor.
    for k in (0.0, 0.5, 1.0):
        zs = [box.point((x, y, k))[2] for x in (0.0, 1.0) for y in (0.0, 1.0)]
        assert np.allclose(zs, top + k * (bottom - top))
    # Its columns run along the sun, away from it.
    column = box.point((0.5, 0.5, 1.0)) - box.point((0.5, 0.5, 0.0))
    assert np.allclose(np.cross(column, sun), 0.0, atol=1e-6) and np.dot(column, sun) < 0
    # A point just under the top and one on the floor, at the same xy, both map inside.
    for z in (top - 1.0, bottom + 1.0):
        unit = rows[:, :3] @ np.array([0.0, 0.0, z]) + rows[:, 3]
        assert np.all(unit >= 0) and np.all(unit <= 1), unit

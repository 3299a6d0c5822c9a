"""A layered sky's data (core/cloudlayers.py, docs/layers.md): [[cloud_layers]] in presets, read, refused
and written back, and the altitudes the renderer takes from a stack of layers."""

import numpy as np
import pytest

from nubis_addon.core import cloudlayers, fields, presets, userpresets
from nubis_addon.core.errors import NubisError
from nubis_addon.core.state import CloudState

TWO = b"""
[preset]
name = "Two"
[layer]
bottom = 1000.0
top = 2000.0
[density]
cover = 0.6
[[field.layers]]
kind = "constant"
channel = "coverage"
value = 0.7

[[cloud_layers]]
name = "Altocumulus"
[cloud_layers.layer]
bottom = 5000.0
top = 6000.0
[cloud_layers.noise]
lf_period = 5000.0
[cloud_layers.wind]
speed = 20.0
[[cloud_layers.field.layers]]
name = "Cells"
kind = "perlin"
channel = "coverage"
scale = 4000.0
"""


def _two(text: bytes = TWO):
    return presets.preset_from_bytes(text)


def test_a_further_layer_reads_its_own_tables_and_copies_the_rest_from_the_first():
    p = _two()
    assert len(p.cloud_layers) == 1
    alto = p.cloud_layers[0]
    assert alto.name == "Altocumulus" and alto.enabled
    assert (alto.params["layer_bottom"], alto.params["layer_top"]) == (5000.0, 6000.0)
    assert alto.params["noise_lf_period"] == 5000.0 and alto.params["wind_speed"] == 20.0
    # What the table leaves out is the first layer's.
    assert alto.params["density_cover"] == 0.6 == p.params["density_cover"]
    assert alto.params["noise_hf_period"] == p.params["noise_hf_period"]
    assert [layer["name"] for layer in alto.field_layers] == ["Cells"]
    assert [layer["kind"] for layer in p.layers] == ["constant"]


def test_a_further_layer_without_a_stack_of_its_own_copies_the_first_layers():
    p = presets.preset_from_bytes(
        TWO + b'\n[[cloud_layers]]\nname = "Same"\n[cloud_layers.layer]\nbottom = 7000.0\ntop = 7600.0\n'
    )
    same = p.cloud_layers[1]
    assert same.field_layers == p.layers and same.field_layers is not p.layers
    assert same.field_layers[0] is not p.layers[0]


def test_every_shipped_preset_without_layers_reads_as_one_layer():
    """A preset with no [[cloud_layers]] is a sky of one layer, the preset's own; the layered ones hold
    the layers their files list, and every stack is one the sky can draw."""
    layered = {"altocumulus_over_stratocumulus": 1, "layered_overcast": 1}
    for name in presets.list_presets():
        p = presets.load_preset(name)
        text = p.path.read_text(encoding="utf-8")
        assert len(p.cloud_layers) == text.count("[[cloud_layers]]") == layered.get(name, 0), name
        ranges = [("first", p.params["layer_bottom"], p.params["layer_top"])]
        ranges += [(c.name, c.params["layer_bottom"], c.params["layer_top"]) for c in p.cloud_layers]
        cloudlayers.check_stack(ranges)


def _with(extra: str) -> bytes:
    return TWO + extra.encode()


def _layer(name: str, bottom: float, top: float) -> str:
    return f'\n[[cloud_layers]]\nname = "{name}"\n[cloud_layers.layer]\nbottom = {bottom}\ntop = {top}\n'


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (_with(_layer("Low", 1800.0, 2500.0)), "'the preset's own layer' and 'Low' overlap by 200 m"),
        (
            _with(_layer("A", 7000.0, 8000.0) + _layer("B", 9000.0, 9500.0) + _layer("C", 10000.0, 11000.0)),
            "a sky holds at most 4 cloud layers",
        ),
        (_with(_layer("High", 19000.0, 21000.0)), "reaches 21000 m, above the 20000 m"),
        (
            _with('\n[[cloud_layers]]\nname = "Sky"\n[cloud_layers.layer]\ndraw_radius = 5000.0\n'),
            "cloud_layers[1].layer.draw_radius is the sky's, shared by every layer",
        ),
        (_with('\n[[cloud_layers]]\nname = "Sky"\n[cloud_layers.sun]\nstrength = 2.0\n'), "unknown entry 'sun'"),
        (_with('\n[[cloud_layers]]\nname = ""\n'), "cloud_layers[1].name must be a name"),
        (_with(_layer("Altocumulus", 7000.0, 8000.0)), 'another cloud layer is named "Altocumulus"'),
        (
            _with('\n[[cloud_layers]]\nname = "T"\n[cloud_layers.layer]\nbottom = 7000.0\ntop = 6500.0\n'),
            "has its top (6500.0 m) less than 0.001 m above its base (7000.0 m)",
        ),
        (  # passed the preset check and was refused by render as "5000 at or under 5000"
            _with('\n[[cloud_layers]]\nname = "T"\n[cloud_layers.layer]\nbottom = 5000.0\ntop = 5000.000000001\n'),
            "has its top (5000.000000001 m) less than 0.001 m above its base (5000.0 m)",
        ),
        (_with('\n[[cloud_layers]]\nname = "Alto\\u001b[31m"\n'), "holds the control character U+001B"),
        (_with('\n[[cloud_layers]]\nname = "A\\u0000B"\n'), "holds the control character U+0000"),
        (b'[preset]\nname = "Line\\nbreak"\n', 'preset.name "Line\\nbreak" holds the control character U+000A'),
        (
            b'[preset]\nname = "x"\n[layer]\nbottom = 1000.0\ntop = 1000.0000001\n',
            "layer.top 1000.0000001, layer.bottom 1000.0",
        ),
        (b'[preset]\nname = "x"\ncloud_layers = 3\n', "unknown setting preset.cloud_layers"),
        (b'[preset]\nname = "x"\n[cloud_layers]\nname = "y"\n', "must be written as [[cloud_layers]] tables"),
        (
            _with(
                '\n[[cloud_layers]]\nname = "T"\n[cloud_layers.layer]\nbottom = 7000.0\ntop = 8000.0\n'
                '[[cloud_layers.field.layers]]\nkind = "voronoi"\n'
            ),
            "cloud_layers[1]: field.layers[0].kind",
        ),
    ],
)
def test_a_stack_the_sky_cannot_draw_is_refused_in_one_sentence(text: bytes, message: str):
    with pytest.raises(NubisError) as err:
        presets.preset_from_bytes(text)
    assert message in str(err.value), str(err.value)
    assert "\n" not in str(err.value)


def test_a_saved_layered_preset_reads_back_the_same():
    p = _two()
    again = presets.preset_from_bytes(userpresets.dump_preset(p).encode())
    assert len(again.cloud_layers) == 1
    first, second = p.cloud_layers[0], again.cloud_layers[0]
    assert (first.name, first.enabled, first.params) == (second.name, second.enabled, second.params)
    assert first.field_layers == second.field_layers
    assert again.params == p.params and again.layers == p.layers


def _field(value_a: float, res: int = 8, lo: float = 0.0, hi: float = 1.0):
    base = fields.base_fields(res)
    a, b = base["a"].copy(), base["b"].copy()
    a[..., 0] = value_a
    b[..., 1], b[..., 2] = lo, hi
    return a, b


def test_the_shell_spans_every_drawn_layer_and_extents_never_share_an_altitude():
    a, b = _field(0.5)
    state = CloudState(field_a=a, field_b=b)
    state.params.update(layer_bottom=1000.0, layer_top=2000.0)
    # The upper layer's min height reaches a whole thickness under its base: into the free air above the
    # first layer, never into it.
    a2, b2 = _field(0.5, lo=-3.0, hi=1.0)
    upper = cloudlayers.LayerField("alto", {**state.params, "layer_bottom": 3000.0, "layer_top": 3500.0}, a2, b2)
    state.cloud_layers = (upper,)
    assert state.shell() == (1000.0, 3500.0)
    assert cloudlayers.disjoint_extents(state.drawn_layers()) == [(1000.0, 2000.0), (2000.0, 3500.0)]
    # Switched off, the first layer no longer bounds the one above it.
    state.first_layer_drawn = False
    assert state.shell() == (1500.0, 3500.0)
    assert len(state.drawn_layers()) == 1


def test_a_new_layer_goes_where_the_sky_has_room():
    base = presets.preset_from_bytes(TWO).params
    own = cloudlayers.new_layer_params(base, [(1000.0, 2000.0), (5000.0, 6000.0)])
    assert own["layer_bottom"] == 6250.0 and own["layer_top"] == 7250.0
    own = cloudlayers.new_layer_params(base, [(15000.0, 19800.0)])
    assert own["layer_top"] == 15000.0 - 250.0 and own["layer_bottom"] == 13750.0
    with pytest.raises(NubisError, match="no free altitudes"):
        cloudlayers.new_layer_params(base, [(0.0, 19990.0)])
    assert np.isfinite(own["layer_bottom"])


@pytest.mark.parametrize(
    ("bottom", "top", "drawn"),
    [(5000.0, 5000.001, True), (5000.0, 5000.0005, False), (19999.0, 20000.0, True), (0.0, 0.001, True)],
)
def test_the_thinnest_layer_is_the_same_for_a_preset_and_the_scene_that_stores_it_in_float32(bottom, top, drawn):
    """A scene stores altitudes in float32 (5000.001 is 5000.0009765625): the check takes a gap within one
    float32 step of the rule's 1 mm, so what a preset passes the scene renders."""
    stored = (float(np.float32(bottom)), float(np.float32(top)))
    for b, t in ((bottom, top), stored):
        if drawn:
            cloudlayers.check_stack([("L", b, t)])
        else:
            with pytest.raises(NubisError, match="less than 0.001 m above its base"):
                cloudlayers.check_stack([("L", b, t)])

"""A field channel's least and greatest value, remembered per array (core/fieldstats.py): what the
layers' extents and the cirrus check read at every redraw without reducing a whole field each time."""

import gc

import numpy as np

from nubis_addon.core import cloudlayers, fieldstats
from nubis_addon.core.state import CloudState


def field(max_height=1.0, min_height=0.0, size=64):
    b = np.zeros((size, size, 4), np.float32)
    b[..., 1] = min_height
    b[..., 2] = max_height
    return b


def test_the_values_are_the_channels_and_are_remembered_until_edited():
    b = field()
    b[3, 5, 2] = 1.4
    b[7, 1, 1] = -0.2
    assert fieldstats.channel_max(b, 2) == np.float32(1.4)
    assert fieldstats.channel_min(b, 1) == np.float32(-0.2)
    b[9, 9, 2] = 2.0  # in place, unannounced: the remembered value stands (what `edited` is for)
    assert fieldstats.channel_max(b, 2) == np.float32(1.4)
    fieldstats.edited(b)
    assert fieldstats.channel_max(b, 2) == 2.0
    assert fieldstats.channel_min(b, 1) == np.float32(-0.2)


def test_each_array_has_its_own_values_and_they_go_with_it():
    a, b = field(1.2), field(1.2)
    b[0, 0, 2] = 1.5
    assert (fieldstats.channel_max(a, 2), fieldstats.channel_max(b, 2)) == (np.float32(1.2), 1.5)
    held = len(fieldstats._REMEMBERED)
    del a, b
    gc.collect()
    assert len(fieldstats._REMEMBERED) == held - 2
    # A new array in the place of a dead one is read afresh, never given the dead one's values.
    for _ in range(20):
        c = field(0.5)
        assert fieldstats.channel_max(c, 2) == 0.5
        del c


def test_a_layers_extent_and_the_sky_shell_follow_an_announced_edit():
    """The edit a live brush makes (blender/sidebar/paint.py): the extent read after `edited` sees it."""
    params = {"layer_bottom": 1000.0, "layer_top": 2000.0}
    b = field()
    layer = cloudlayers.LayerField("", params, np.zeros_like(b), b)
    assert layer.extent() == (1000.0, 2000.0)
    b[10:12, 10:12, 2] = 1.5
    fieldstats.edited(b)
    assert layer.extent() == (1000.0, 2500.0)


def test_the_cirrus_check_reads_the_remembered_cover():
    c = np.zeros((32, 32, 4), np.float32)
    state = CloudState(params={"cirrus_coverage": 1.0}, field_c=c)
    assert not state.has_cirrus()
    c[4, 4, 0] = 0.3
    fieldstats.edited(c)
    assert state.has_cirrus()
    assert not CloudState(params={"cirrus_coverage": 0.0}, field_c=c).has_cirrus()


def test_a_layers_reach_channels_are_its_fields_greatest_top_type_and_heights():
    """What the view march bounds a layer's clouds by (nubis_layer_reach): the greatest top type, min
    height and max height of its field, each over every column."""
    a = np.zeros((16, 16, 4), np.float32)
    b = field(max_height=0.9, min_height=0.05, size=16)
    a[..., 2] = 0.3
    a[2, 3, 2], b[5, 6, 1], b[7, 8, 2] = 0.8, 0.2, 1.3
    layer = cloudlayers.LayerField("", {"layer_bottom": 0.0, "layer_top": 1.0}, a, b)
    assert layer.reach_channels() == (np.float32(0.8), np.float32(0.2), np.float32(1.3), 0.0)

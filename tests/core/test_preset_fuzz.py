"""Fuzzing the preset loader: every generated mutation of every preset either loads or raises the one
clean error (NubisError, one line, values quoted as TOML). In-process and seeded, so a failure
replays; no Blender needed."""

import datetime
import math
import pickle
import random
import re
import tomllib

import pytest

from nubis_addon.core import schema
from nubis_addon.core.errors import NubisError
from nubis_addon.core.presets import (
    list_presets,
    parse_preset,
    preset_dir,
    preset_from_bytes,
)

MUTATIONS_PER_PRESET = 10_000
TEXT_SHARE = 0.15  # truncations and random bytes go through the TOML parser, which is the slow part

_ODD_VALUES = [
    True,
    False,
    0,
    -1,
    1,
    2**31,
    2**63 - 1,
    -(2**63),
    10**400,
    0.0,
    -0.0,
    1e-300,
    1e300,
    -1e300,
    math.inf,
    -math.inf,
    math.nan,
    "",
    "default",
    "perlin",
    "replace",
    "coverage",
    "AgX",
    "Layer 1",
    "\x00\u202e",
    "x" * 500,
    [],
    [1.0],
    [0.0, 0.0],
    [0.0, 0.0, 1e30],
    [1.0, 1.0, 1.0],
    [0.0, 1.0, 0.0, 1.0],
    [math.nan, 0.0, 0.0],
    ["a", "b", "c"],
    [[1.0]],
    {},
    {"a": 1},
    datetime.date(1979, 5, 27),
    datetime.datetime(1979, 5, 27, 7, 32),
    datetime.time(7, 32),
]


def _copy(value):
    if isinstance(value, dict):
        return {k: _copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_copy(v) for v in value]
    return value


def _leaf_paths(data, path=()):
    """The key path of every value in the parsed preset, computed once per preset."""
    if isinstance(data, dict):
        items = data.items()
    elif isinstance(data, list):
        items = enumerate(data)
    else:
        return
    for key, value in items:
        yield (*path, key)
        yield from _leaf_paths(value, (*path, key))


def _spot(data, paths, rng):
    """(container, key) of a random original path in the mutated copy, or None where it is gone."""
    *head, last = rng.choice(paths)
    node = data
    for key in head:
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            return None
    if isinstance(node, dict) and last in node or isinstance(node, list) and isinstance(last, int) and last < len(node):
        return node, last
    return None


def _odd_value(rng: random.Random):
    if rng.random() < 0.5:
        return _copy(rng.choice(_ODD_VALUES))
    kind = rng.randrange(4)
    if kind == 0:
        return rng.uniform(-1e7, 1e7) * 10 ** rng.randint(-6, 6)
    if kind == 1:
        return rng.randint(-(2**40), 2**40)
    if kind == 2:
        return [rng.uniform(-10, 10) for _ in range(rng.randrange(6))]
    return "".join(chr(rng.randrange(32, 0x2FF)) for _ in range(rng.randrange(12)))


def _known_keys():
    keys = {sec: list(table) for sec, table in schema.EXTRA_SECTIONS.items()}
    for p in schema.PRESET_SCENE:
        keys.setdefault(p.section, []).append(p.name)
    return keys


KNOWN = _known_keys()


def _mutate(template: bytes, paths: list, rng: random.Random) -> dict:
    data = pickle.loads(template)  # a deep copy, fast
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        op = rng.randrange(7)
        spot = _spot(data, paths, rng) if op <= 3 else None
        if op <= 2 and spot:  # a value of another type or range
            container, key = spot
            container[key] = _odd_value(rng)
        elif op == 3 and spot:  # a missing key
            container, key = spot
            if isinstance(container, dict):
                del container[key]
            else:
                container.pop(key)
        elif op == 4:  # an extra or misplaced key
            section = rng.choice([*KNOWN, "bogus", "storms", "field"])
            table = data.setdefault(section, {}) if rng.random() < 0.9 else data
            name = rng.choice(
                [
                    *rng.choice(list(KNOWN.values())),
                    "bogus",
                    "layers",
                    *schema.FIELD_LAYER_BY_NAME,
                    *schema.STORM_BY_NAME,
                ]
            )
            if isinstance(table, dict):
                table[name] = _odd_value(rng)
            else:
                data[name] = _odd_value(rng)
        elif op == 5:  # many storms or layers, or a layer or storm of odd keys
            count = rng.choice((0, 1, 4, 5, 100, 129, 300))
            if rng.random() < 0.5:
                data["storms"] = [{"x": rng.uniform(-1e7, 1e7)} for _ in range(count)]
            else:
                layer = {k: _odd_value(rng) for k in rng.sample(list(schema.FIELD_LAYER_BY_NAME), 3)}
                if not isinstance(data.get("field"), dict):
                    data["field"] = {}
                data["field"]["layers"] = [_copy(layer) for _ in range(count)]
        else:  # a whole section replaced by a value
            section = rng.choice([*data] or ["sun"])
            data[section] = _odd_value(rng)
    return data


def _mutate_text(raw: bytes, rng: random.Random) -> bytes:
    op = rng.randrange(4)
    if op == 0:
        return raw[: rng.randrange(len(raw) + 1)]
    if op == 1:
        pos = rng.randrange(len(raw) + 1)
        return raw[:pos] + rng.randbytes(rng.randrange(1, 16)) + raw[pos:]
    if op == 2:
        out = bytearray(raw)
        for _ in range(rng.randrange(1, 8)):
            out[rng.randrange(len(out))] = rng.randrange(256)
        return bytes(out)
    return b"a = " + b"[" * rng.randrange(100, 1500)  # past the parser's recursion limit


_PYTHON_REPR = re.compile(r"\b(True|False|None)\b|datetime\.|\\x[0-9a-f]{2}")


def _check_clean(err: NubisError) -> None:
    text = str(err)
    assert text and "\n" not in text, repr(text)
    assert not _PYTHON_REPR.search(text), text  # values are quoted as TOML, never as Python reprs


@pytest.mark.parametrize("name", list_presets())
def test_every_mutation_loads_or_raises_the_clean_error(name):
    path = preset_dir() / f"{name}.toml"
    raw = path.read_bytes()
    data = tomllib.loads(raw.decode())
    paths = list(_leaf_paths(data))
    template = pickle.dumps(data)
    rng = random.Random(f"nubis-fuzz-{name}")
    loaded = refused = 0
    for i in range(MUTATIONS_PER_PRESET):
        text_mutation = rng.random() < TEXT_SHARE
        try:
            if text_mutation:
                preset = preset_from_bytes(_mutate_text(raw, rng), path)
            else:
                preset = parse_preset(_mutate(template, paths, rng), path)
        except NubisError as err:
            _check_clean(err)
            refused += 1
            continue
        except Exception as err:  # anything but the one clean error is a defect in the loader
            pytest.fail(f"mutation {i} of {name} raised {type(err).__name__}: {err}")
        loaded += 1
        for key, value in preset.params.items():
            p = schema.BY_KEY[key]
            if p.kind in ("int", "float") and p.min is not None:
                assert p.min <= value <= p.max, (i, key, value)
        assert len(preset.storms) <= 4 and len(preset.layers) <= 128
    assert loaded + refused == MUTATIONS_PER_PRESET
    assert loaded > 100 and refused > 100, (loaded, refused)  # both outcomes are exercised

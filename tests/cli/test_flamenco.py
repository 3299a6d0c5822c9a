"""The Flamenco job type (nubis_addon/flamenco/nubis_vdb_bake.js) compiled with Node.js against a stand-in for
the Manager's `author` and `path` API: one task per chunk of frames, each a `blender-render` command
running `--command nubis bake` with the options, and refusals that say what to do. Flamenco itself
is not installed here; the commands each task runs are the ones tests/test_bake_sequence.py runs."""

import json
import shutil
import subprocess
from pathlib import Path

import pytest

JOB = Path(__file__).resolve().parents[2] / "nubis_addon" / "flamenco" / "nubis_vdb_bake.js"

HARNESS = """
const fs = require("fs");
const nodePath = require("path");
const tasks = [];
global.path = { join: (...p) => nodePath.posix.join(...p) };
global.author = {
  Task: (name, type) => ({ name, type, commands: [], addCommand(c) { this.commands.push(c); } }),
  Command: (type, params) => ({ type, params }),
};
eval(fs.readFileSync(process.argv[1], "utf8") + "; global.compileJob = compileJob; global.JOB_TYPE = JOB_TYPE;");
const settings = JSON.parse(process.argv[2]);
try {
  compileJob({ settings, addTask: (t) => tasks.push(t) });
  console.log(JSON.stringify({ tasks, keys: JOB_TYPE.settings.map((s) => s.key) }));
} catch (e) {
  console.log(JSON.stringify({ error: String(e) }));
}
"""


def compile_job(**settings):
    node = shutil.which("node")
    assert node, "Node.js is needed to check the Flamenco job type: apt-get install nodejs"
    base = {
        "frames": "1-10",
        "chunk_size": 4,
        "vdb_output_dir": "/farm/shot010/vdb",
        "vdb_file_name": "clouds_####.vdb",
        "voxel_size": 25.0,
        "camera_only": True,
        "half": False,
        "velocity": True,
        "blendfile": "/farm/shot010/clouds.blend",
    }
    base.update(settings)
    out = subprocess.run([node, "-e", HARNESS, str(JOB), json.dumps(base)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def test_job_type_compiles_a_sequence_into_chunked_bake_tasks():
    job = compile_job()
    assert [t["name"] for t in job["tasks"]] == ["bake-1-4", "bake-5-8", "bake-9-10"]
    cmd = job["tasks"][0]["commands"][0]
    assert job["tasks"][0]["type"] == "blender" and cmd["type"] == "blender-render"
    assert cmd["params"]["blendfile"] == "/farm/shot010/clouds.blend"
    assert cmd["params"]["args"] == [
        "--command", "nubis", "bake", "--frames", "1-4", "--out", "/farm/shot010/vdb/clouds_####.vdb",
        "--voxel-size", "25", "--camera-only", "--velocity",
    ]  # fmt: skip
    assert {"frames", "chunk_size", "blendfile", "half", "velocity"} <= set(job["keys"])
    single = compile_job(frames="7", chunk_size=1, voxel_size=0.0, camera_only=False, velocity=False, half=True)
    assert [t["commands"][0]["params"]["args"][3:] for t in single["tasks"]] == [
        ["--frames", "7", "--out", "/farm/shot010/vdb/clouds_####.vdb", "--half"]
    ]


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"vdb_file_name": "clouds.vdb"}, "needs ####"),
        ({"frames": "10-1"}, "write 1-10"),
        ({"frames": "1,3"}, "'A-B' or a single frame"),
    ],
)
def test_job_type_refuses_bad_settings_with_a_message(settings, message):
    assert message in compile_job(**settings)["error"]

// SPDX-License-Identifier: GPL-3.0-or-later
//
// Flamenco custom job type: bake a Nubis cloudscape to an OpenVDB sequence on the farm.
// Copy this file into the Flamenco Manager's `scripts/` folder and restart the Manager; the job type
// "Nubis VDB Bake" then appears in Blender's Flamenco add-on (docs/flamenco.md).
//
// Each task runs `blender -b FILE --command nubis bake --frames A-B --out .../clouds_####.vdb ...`
// on a worker for one chunk of frames. Every file is written atomically by the extension (a
// staging folder, then a rename), so a task that fails or a worker that dies never leaves a
// half-written frame: Flamenco requeues the task and the frame is baked again.

const JOB_TYPE = {
  label: "Nubis VDB Bake",
  description: "Bake Nubis clouds to an OpenVDB sequence, one task per chunk of frames",
  settings: [
    {
      key: "frames",
      type: "string",
      required: true,
      eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
      evalInfo: { showLinkButton: true, description: "Scene frame range" },
      description: "Frames to bake: 'A-B' or a single frame",
    },
    {
      key: "chunk_size",
      type: "int32",
      default: 1,
      description: "Frames baked by one task (one Blender start per task)",
      visible: "submission",
    },
    {
      key: "vdb_output_dir",
      type: "string",
      subtype: "dir_path",
      required: true,
      visible: "submission",
      description: "Folder the VDB files go to (all workers must reach it)",
    },
    {
      key: "vdb_file_name",
      type: "string",
      required: true,
      default: "clouds_####.vdb",
      visible: "submission",
      description: "File name; the #### become the frame number (Blender's VDB-sequence convention)",
    },
    {
      key: "voxel_size",
      type: "float",
      default: 0.0,
      visible: "submission",
      description: "Voxel edge in metres (0: the scene's Bake setting)",
    },
    { key: "camera_only", type: "bool", default: false, visible: "submission", description: "Bake only what the scene camera sees" },
    { key: "half", type: "bool", default: false, visible: "submission", description: "Half-float grids (half the disk space)" },
    { key: "velocity", type: "bool", default: true, visible: "submission", description: "A velocity grid for motion blur" },
    // Set by Blender's Flamenco add-on.
    { key: "blendfile", type: "string", required: true, description: "Path of the .blend file to bake", visible: "web" },
  ],
};

// "A-B" or "N" to [first, last]; anything else is refused with a message the artist sees.
function parseFrames(text) {
  const m = /^\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?$/.exec(String(text));
  if (!m) {
    throw `frames must be 'A-B' or a single frame, not '${text}'`;
  }
  const first = parseInt(m[1], 10);
  const last = m[2] === undefined ? first : parseInt(m[2], 10);
  if (last < first) {
    throw `frames ${text}: the last frame comes before the first; write ${last}-${first}`;
  }
  return [first, last];
}

// Contiguous chunks of at most `size` frames: ["1-4", "5-8", "9"].
function frameChunks(first, last, size) {
  const chunks = [];
  const step = Math.max(1, size | 0);
  for (let a = first; a <= last; a += step) {
    const b = Math.min(a + step - 1, last);
    chunks.push(a === b ? `${a}` : `${a}-${b}`);
  }
  return chunks;
}

function bakeArgs(settings, chunk) {
  const args = ["--command", "nubis", "bake", "--frames", chunk, "--out", path.join(settings.vdb_output_dir, settings.vdb_file_name)];
  if (settings.voxel_size > 0) {
    args.push("--voxel-size", `${settings.voxel_size}`);
  }
  if (settings.camera_only) args.push("--camera-only");
  if (settings.half) args.push("--half");
  if (settings.velocity) args.push("--velocity");
  return args;
}

function compileJob(job) {
  const settings = job.settings;
  if (settings.vdb_file_name.indexOf("#") < 0) {
    throw `the file name '${settings.vdb_file_name}' needs #### where the frame number goes (clouds_####.vdb)`;
  }
  const [first, last] = parseFrames(settings.frames);
  for (const chunk of frameChunks(first, last, settings.chunk_size)) {
    const task = author.Task(`bake-${chunk}`, "blender");
    task.addCommand(
      author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: [],
        blendfile: settings.blendfile,
        args: bakeArgs(settings, chunk),
      }),
    );
    job.addTask(task);
  }
}

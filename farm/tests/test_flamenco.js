// The Flamenco job type farm/flamenco/raysplats_render.js under a stand-in of the Manager's job compiler
// (flamenco_standin.js): its tasks, their command lines, its chunks (those of the OpenJD template's TASK_CHUNKING,
// taken from openjd-model 0.13's StepParameterSpaceIterator for the same frames and chunk size) and its refusals.
// (test_openjd.py checks the command lines against the ones the OpenJD template runs.)
//   node --test farm/tests/test_flamenco.js
"use strict";
const assert = require("node:assert/strict");
const path = require("node:path");
const test = require("node:test");
const { loadJobType, blenderCommandLine, shellSplit } = require("./flamenco_standin.js");

const JOB_TYPE_FILE = path.join(__dirname, "..", "flamenco", "raysplats_render.js");
const SETTINGS = { frames: "1-7", chunk_size: 3, threads: 0, render_output_path: "/renders/shot/frame_####",
                   blendfile: "/shots/shot.blend", format: "PNG" };
const VARIABLES = { blender: "/opt/blender/blender", blenderArgs: "-b -y" };

function chunksOf(settings) {
    return loadJobType(JOB_TYPE_FILE).compile({ ...SETTINGS, ...settings })
        .map((task) => blenderCommandLine(task.commands[0], VARIABLES).at(-1));
}

test("every task is one blender-render command with the template's arguments", () => {
    const tasks = loadJobType(JOB_TYPE_FILE).compile(SETTINGS);
    assert.deepEqual(tasks.map((t) => t.name), ["render-1-3", "render-4-5", "render-6-7"]);
    for (const task of tasks) {
        assert.equal(task.type, "blender");
        assert.equal(task.commands.length, 1);
        assert.equal(task.commands[0].name, "blender-render");
    }
    assert.deepEqual(blenderCommandLine(tasks[1].commands[0], VARIABLES), [
        "/opt/blender/blender", "-b", "-y", "/shots/shot.blend", "--engine", "RAYSPLATS", "--threads", "0",
        "--render-output", "/renders/shot/frame_####", "--render-format", "PNG", "--render-frame", "4..5"]);
});

test("chunks are OpenJD's CONTIGUOUS chunks", () => {
    // Reference values: openjd-model's StepParameterSpaceIterator over a CHUNK[INT] range with these settings.
    assert.deepEqual(chunksOf({ frames: "1-7", chunk_size: 3 }), ["1..3", "4..5", "6..7"]);
    assert.deepEqual(chunksOf({ frames: "1-5", chunk_size: 2 }), ["1..2", "3..4", "5..5"]);
    assert.deepEqual(chunksOf({ frames: "1-10", chunk_size: 4 }), ["1..4", "5..7", "8..10"]);
    assert.deepEqual(chunksOf({ frames: "1-10,20-22", chunk_size: 5 }), ["1..5", "6..10", "20..22"]);
    assert.deepEqual(chunksOf({ frames: "1-10:3", chunk_size: 2 }), ["1..1", "4..4", "7..7", "10..10"]);
    assert.deepEqual(chunksOf({ frames: "12, 10-11", chunk_size: 10 }), ["10..12"]);
    assert.deepEqual(chunksOf({ frames: "5", chunk_size: 10 }), ["5..5"]);
});

test("bad settings are refused with the reason", () => {
    const jobType = loadJobType(JOB_TYPE_FILE);
    assert.throws(() => jobType.compile({ ...SETTINGS, format: "FFMPEG" }), /not "FFMPEG"/);
    assert.throws(() => jobType.compile({ ...SETTINGS, frames: "1-3,2" }), /frame 2 is given twice/);
    assert.throws(() => jobType.compile({ ...SETTINGS, frames: "-5-3" }), /not negative/);
    assert.throws(() => jobType.compile({ ...SETTINGS, frames: "1-5:-1" }), /does not lead from 1 to 5/);
    assert.throws(() => jobType.compile({ ...SETTINGS, chunk_size: 0 }), /chunk_size/);
});

test("job type settings: what the Blender add-on of Flamenco shows and evaluates", () => {
    const { JOB_TYPE } = loadJobType(JOB_TYPE_FILE);
    const byKey = Object.fromEntries(JOB_TYPE.settings.map((s) => [s.key, s]));
    assert.deepEqual(Object.keys(byKey).sort(),
                     ["blendfile", "chunk_size", "format", "frames", "render_output_path", "threads"]);
    assert.equal(byKey.format.eval, "C.scene.render.image_settings.file_format");
    assert.deepEqual([...byKey.format.choices], ["PNG", "OPEN_EXR", "OPEN_EXR_MULTILAYER", "TIFF", "JPEG"]);
    for (const setting of JOB_TYPE.settings) assert.ok(setting.description, setting.key);
});

test("the stand-in splits exeArgs as the Worker's shlex", () => {
    assert.deepEqual(shellSplit(`-b -y --python-expr "import bpy" 'a b' c\\ d`),
                     ["-b", "-y", "--python-expr", "import bpy", "a b", "c d"]);
});

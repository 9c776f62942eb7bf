// SPDX-License-Identifier: GPL-3.0-or-later
// Flamenco job type: renders a frame range of a .blend with the RaySplats engine, a chunk of frames per task. Its
// settings are those of the Open Job Description template farm/openjd/raysplats_render.yaml, and each task runs the
// command line that template runs for the same chunk:
//   {blender} {blenderArgs} <blendfile> --engine RAYSPLATS --threads <threads> --render-output <render_output_path>
//             --render-format <format> --render-frame <first>..<last>
// ({blender} and {blenderArgs} are the Manager's variables, "-b -y" by default, as the template's "-b -y"). Chunks are
// that template's: the frames split into ceil(count / chunk_size) contiguous chunks as even as can be (Open Job
// Description's TASK_CHUNKING, CONTIGUOUS), not Flamenco's own frameChunker (full chunks and a short last one).
// Install: copy this file into the Manager's `scripts/` folder (beside flamenco-manager) and restart it; the Blender
// add-on then offers "RaySplats Render". Workers need RaySplats in their Blender (farm/install_worker.py).

const OUTPUT_FORMATS = ["PNG", "OPEN_EXR", "OPEN_EXR_MULTILAYER", "TIFF", "JPEG"];

const JOB_TYPE = {
    label: "RaySplats Render",
    description: "Render frames with the RaySplats engine, a chunk of frames per task",
    settings: [
        // Settings for artists to determine:
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          evalInfo: { showLinkButton: true, description: "Scene frame range" },
          description: "Frames to render, not negative. Examples: '47', '1-30', '3,5-10,47-327', '1-100:2'" },
        { key: "chunk_size", type: "int32", default: 10, propargs: { min: 1, max: 150 }, visible: "submission",
          description: "Number of frames to render in one Blender process (one task)" },
        { key: "threads", type: "int32", default: 0, propargs: { min: 0, max: 1024 }, visible: "submission",
          description: "Render threads per task (0: every core). The frames do not depend on it" },
        { key: "render_output_path", type: "string", subtype: "file_path", required: true,
          eval: "bpy.path.abspath(C.scene.render.filepath)", visible: "submission",
          description: "Output path of the frames, with # for the frame number (e.g. /renders/shot/frame_####)" },
        // Automatically evaluated settings:
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "Path of the .blend to render (its splats are in it: no other input is needed)" },
        { key: "format", type: "string", required: true, choices: OUTPUT_FORMATS,
          eval: "C.scene.render.image_settings.file_format", visible: "web",
          description: "Image format of the frames" },
    ]
};

function compileJob(job) {
    print("RaySplats render job submitted");
    const settings = job.settings;
    if (OUTPUT_FORMATS.indexOf(settings.format) < 0) {
        throw `RaySplats Render writes frames as ${OUTPUT_FORMATS.join(", ")}, not "${settings.format}"`;
    }
    const chunkSize = Number(settings.chunk_size);
    if (!Number.isInteger(chunkSize) || chunkSize < 1) {
        throw `chunk_size must be a whole number of frames, 1 or more, not "${settings.chunk_size}"`;
    }
    const threads = settings.threads === undefined ? 0 : Number(settings.threads);
    for (const chunk of contiguousChunks(parseFrames(settings.frames), chunkSize)) {
        const task = author.Task(`render-${chunk[0]}-${chunk[1]}`, "blender");
        task.addCommand(author.Command("blender-render", {
            exe: "{blender}",
            exeArgs: "{blenderArgs}",
            argsBefore: [],
            blendfile: settings.blendfile,
            args: [
                "--engine", "RAYSPLATS",
                "--threads", `${threads}`,
                "--render-output", settings.render_output_path,
                "--render-format", settings.format,
                "--render-frame", `${chunk[0]}..${chunk[1]}`,
            ],
        }));
        job.addTask(task);
    }
}

// Frames of an integer range expression ("1-10", "1,3,7-20:2", "10-1:-2"), as Open Job Description reads it: items
// separated by commas, each a frame, "first-last" or "first-last:step"; no frame twice. Sorted.
function parseFrames(text) {
    const frames = [];
    for (const item of `${text}`.split(",")) {
        const match = /^\s*(\d+)\s*(?:-\s*(\d+)\s*(?::\s*(-?\d+)\s*)?)?$/.exec(item);
        if (!match) {
            throw `frames: "${item.trim()}" is not a frame, "first-last" or "first-last:step" (of "${text}"; frames are not negative)`;
        }
        const first = Number(match[1]);
        const last = match[2] === undefined ? first : Number(match[2]);
        const step = match[3] === undefined ? 1 : Number(match[3]);
        if (step === 0 || (last - first) * step < 0) {
            throw `frames: the step of "${item.trim()}" does not lead from ${first} to ${last}`;
        }
        for (let frame = first; step > 0 ? frame <= last : frame >= last; frame += step) {
            frames.push(frame);
        }
    }
    frames.sort((a, b) => a - b);
    for (let i = 1; i < frames.length; i++) {
        if (frames[i] === frames[i - 1]) {
            throw `frames: frame ${frames[i]} is given twice in "${text}"`;
        }
    }
    return frames;
}

// [first, last] chunks of sorted frames: each run of consecutive frames split into ceil(count / size) chunks whose
// sizes differ by at most one, the larger ones spread evenly (openjd-model's divide_chunk_sizes, which the
// TASK_CHUNKING extension's CONTIGUOUS chunks follow).
function contiguousChunks(frames, size) {
    const chunks = [];
    let start = 0;
    for (let i = 1; i <= frames.length; i++) {
        if (i < frames.length && frames[i] === frames[i - 1] + 1) continue;
        let first = frames[start];
        for (const count of chunkSizes(size, i - start)) {
            chunks.push([first, first + count - 1]);
            first += count;
        }
        start = i;
    }
    return chunks;
}

function chunkSizes(size, count) {
    const chunkCount = Math.ceil(count / size);
    if (chunkCount >= count) return new Array(count).fill(1);
    if (chunkCount <= 1) return [count];
    const small = Math.floor(count / chunkCount);
    const leftovers = count % chunkCount;
    const sizes = new Array(chunkCount).fill(small);
    for (let i = 0; i < leftovers; i++) sizes[Math.floor((i * chunkCount) / leftovers)] += 1;
    return sizes;
}

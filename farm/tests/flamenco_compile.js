// Compiles a job with a Flamenco job type through the stand-in of the Manager (flamenco_standin.js) and prints, as
// JSON, the job type's settings and each task with the command lines its Worker would run.
//   node flamenco_compile.js JOB_TYPE.js REQUEST.json
// REQUEST: {"settings": {...the job's settings...}, "variables": {"blender": ..., "blenderArgs": ...}}
"use strict";
const fs = require("fs");
const { loadJobType, blenderCommandLine } = require("./flamenco_standin.js");

const [jobTypeFile, requestFile] = process.argv.slice(2);
const request = JSON.parse(fs.readFileSync(requestFile, "utf8"));
const jobType = loadJobType(jobTypeFile);
const tasks = jobType.compile(request.settings).map((task) => ({
    name: task.name,
    type: task.type,
    commands: task.commands.map((command) => ({ name: command.name,
                                                argv: blenderCommandLine(command, request.variables) })),
}));
process.stdout.write(JSON.stringify({ job_type: jobType.JOB_TYPE, tasks }));

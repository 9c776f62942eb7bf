// A stand-in of the Flamenco Manager's job compiler for tests: runs a job type script (JOB_TYPE and compileJob, as
// the Manager's JavaScript engine does) with the globals Flamenco gives it (`author.Task`, `author.Command`, `print`,
// `path`), records the tasks and commands compileJob authors, and turns a blender-render command into the command
// line a Flamenco Worker runs: exe, the shell-split exeArgs, argsBefore, blendfile (when not empty), args
// (internal/worker/command_blender.go), with the Manager's variables ({blender}, {blenderArgs}) replaced.
"use strict";
const fs = require("fs");
const nodePath = require("path");
const vm = require("vm");

function loadJobType(file) {
    const printed = [];
    const author = {
        Task(name, type) {
            const task = { name, type, commands: [], dependencies: [] };
            task.addCommand = (command) => task.commands.push(command);
            task.addDependency = (other) => task.dependencies.push(other.name);
            return task;
        },
        Command(name, parameters) {
            return { name, parameters };
        },
    };
    const context = vm.createContext({
        author,
        print: (...values) => printed.push(values.map(String).join(" ")),
        path: { join: nodePath.posix.join, dirname: nodePath.posix.dirname, basename: nodePath.posix.basename,
                stem: (p) => nodePath.posix.parse(p).name },
    });
    vm.runInContext(fs.readFileSync(file, "utf8") + "\n;this.JOB_TYPE = JOB_TYPE; this.compileJob = compileJob;",
                    context, { filename: file });
    return {
        JOB_TYPE: context.JOB_TYPE,
        printed,
        compile(settings, created = "2026-01-01T00:00:00Z") {
            const tasks = [];
            context.compileJob({ settings: { ...settings }, created, addTask: (task) => tasks.push(task) });
            return tasks;
        },
    };
}

// Splits a command-line string as a POSIX shell would (quotes and backslashes; no expansions), as the Worker's shlex.
function shellSplit(text) {
    const words = [];
    let word = null;
    let quote = null;
    for (let i = 0; i < text.length; i++) {
        const c = text[i];
        if (quote === "'") {
            if (c === "'") quote = null; else word += c;
        } else if (quote === '"') {
            if (c === '"') quote = null;
            else if (c === "\\" && i + 1 < text.length) word += text[++i];
            else word += c;
        } else if (/\s/.test(c)) {
            if (word !== null) { words.push(word); word = null; }
        } else {
            if (word === null) word = "";
            if (c === "'" || c === '"') quote = c;
            else if (c === "\\" && i + 1 < text.length) word += text[++i];
            else word += c;
        }
    }
    if (quote) throw new Error(`unbalanced quote in "${text}"`);
    if (word !== null) words.push(word);
    return words;
}

function expandVariables(value, variables) {
    return value.replace(/\{([A-Za-z0-9_]+)\}/g, (match, name) => (name in variables ? variables[name] : match));
}

function blenderCommandLine(command, variables) {
    if (command.name !== "blender-render") throw new Error(`not a blender-render command: ${command.name}`);
    const p = command.parameters;
    const expand = (value) => expandVariables(`${value}`, variables);
    const argv = [expand(p.exe), ...shellSplit(expand(p.exeArgs || "")), ...(p.argsBefore || []).map(expand)];
    if (p.blendfile) argv.push(expand(p.blendfile));
    return argv.concat((p.args || []).map(expand));
}

module.exports = { loadJobType, shellSplit, blenderCommandLine };

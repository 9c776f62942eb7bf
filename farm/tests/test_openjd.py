# The Open Job Description templates of farm/openjd/, run by openjd-cli (farm/setup_openjd.sh) the way a worker runs
# them, on two local workers at once (two `openjd run` sessions, each given half of the step's tasks as the
# scheduler makes them): every frame equals the single-machine render of the same frames, every converted file
# equals the CLI's conversion. Workers are this Blender with RaySplats installed by farm/install_worker.sh into a
# user folder of their own. Also: a worker without RaySplats fails its task, and the Flamenco job type's tasks run
# the same command lines as the render template's.
import json
import os
import shutil
import subprocess
import time
import unittest

import bpy
import numpy as np

import farm_testing as ft
from farm_testing import st

TEMPLATES = os.path.join(ft.FARM, "openjd")
RENDER = os.path.join(TEMPLATES, "raysplats_render.yaml")
CONVERT = os.path.join(TEMPLATES, "raysplats_convert.yaml")
FRAMES, CHUNK_SIZE = (1, 6), 2
CONVERT_INPUTS = ("small.splat", "small_sh3_inria.ply", "unicorn_sh3.sog")


def openjd_cli():
    """The openjd executable of farm/setup_openjd.sh's venv, or None when PyPI could not give it."""
    result = subprocess.run([os.path.join(ft.FARM, "setup_openjd.sh")], capture_output=True, text=True)
    return result.stdout.strip() or None


class OpenJD(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.openjd = openjd_cli()
        if cls.openjd is None:
            raise unittest.SkipTest("openjd-cli is not installed (farm/setup_openjd.sh could not reach PyPI)")
        cls.venv_python = os.path.join(os.path.dirname(cls.openjd), "python")
        cls.root = st.tmp_file("openjd")
        shutil.rmtree(cls.root, ignore_errors=True)
        os.makedirs(cls.root)
        cls.worker_env = dict(os.environ, BLENDER_USER_RESOURCES=os.path.join(cls.root, "worker_blender"))
        ft.run([os.path.join(ft.FARM, "install_worker.sh"), "--blender", bpy.app.binary_path], env=cls.worker_env)
        cls.blend = os.path.join(cls.root, "shot.blend")
        ft.build_shot(cls.blend, frames=FRAMES)

    def template(self, path):
        """A template as data (read by the openjd venv's PyYAML)."""
        return json.loads(ft.run([self.venv_python, "-c", "import json, sys, yaml; json.dump(yaml.safe_load("
                                  "open(sys.argv[1])), sys.stdout)", path]).stdout)

    def tasks(self, template, step, **parameters):
        """The step's tasks as the scheduler makes them (openjd-model), in the form of `openjd run --tasks`."""
        command = [self.venv_python, os.path.join(ft.HERE, "openjd_tasks.py"), template, step]
        command += [f"{name}={value}" for name, value in parameters.items()]
        return json.loads(ft.run(command).stdout)

    def run_on_workers(self, template, step, tasks, parameters, workers=2, env=None):
        """Runs the tasks in `workers` concurrent `openjd run` sessions (task i on worker i % workers); returns each
        session's (status, log) and the wall time of the whole."""
        processes = []
        started = time.perf_counter()
        for worker in range(workers):
            share = tasks[worker::workers]
            tasks_file = os.path.join(self.root, f"{step}_worker{worker}_tasks.json")
            with open(tasks_file, "w") as out:
                json.dump(share, out)
            command = [self.openjd, "run", template, "--step", step, "--tasks", "file://" + tasks_file]
            command += [argument for name, value in parameters.items() for argument in ("-p", f"{name}={value}")]
            processes.append(subprocess.Popen(command, env=env or self.worker_env, stdout=subprocess.PIPE,
                                              stderr=subprocess.STDOUT, text=True))
        logs = [(process.wait(timeout=600), process.stdout.read()) for process in processes]
        return logs, time.perf_counter() - started

    def render_parameters(self, output):
        return {"BlendFile": self.blend, "Frames": f"{FRAMES[0]}-{FRAMES[1]}", "ChunkSize": CHUNK_SIZE,
                "OutputPath": output, "OutputFormat": "PNG", "Blender": bpy.app.binary_path}

    def test_render_template_on_two_workers_equals_one_machine(self):
        single = os.path.join(self.root, "single", "frame_####")
        started = time.perf_counter()
        ft.run([bpy.app.binary_path, "-b", "-y", self.blend, "--engine", "RAYSPLATS", "--render-output", single,
                "--render-format", "PNG", "--render-frame", f"{FRAMES[0]}..{FRAMES[1]}"], env=self.worker_env)
        single_seconds = time.perf_counter() - started

        farm = os.path.join(self.root, "farm", "frame_####")
        parameters = self.render_parameters(farm)
        tasks = self.tasks(RENDER, "Render", **parameters)
        self.assertEqual(tasks, [{"Frame": "1-2"}, {"Frame": "3-4"}, {"Frame": "5-6"}])
        logs, farm_seconds = self.run_on_workers(RENDER, "Render", tasks, parameters)
        for status, log in logs:
            self.assertEqual(status, 0, log)
        # Each worker rendered its own chunks, in its own Blender processes.
        for worker, (_, log) in enumerate(logs):
            for task in tasks[worker::2]:
                first, last = map(int, task["Frame"].split("-"))
                for frame in range(first, last + 1):
                    self.assertIn(f"Saved: '{ft.frame_path(farm, frame)}'", log)
        with open("/proc/loadavg") as load:
            print(f"\nOpenJD render, frames {FRAMES[0]}-{FRAMES[1]} in chunks of {CHUNK_SIZE} on 2 workers: "
                  f"{farm_seconds:.1f} s; one machine, one Blender: {single_seconds:.1f} s "
                  f"(load {load.read().split()[0]})")

        previous = None
        for frame in range(FRAMES[0], FRAMES[1] + 1):
            expected = ft.load_pixels(ft.frame_path(single, frame))
            actual = ft.load_pixels(ft.frame_path(farm, frame))
            self.assertEqual(np.abs(actual - expected).max(), 0.0, f"frame {frame}")
            self.assertGreater(np.count_nonzero(actual[..., 3] > 0.05), actual[..., 3].size // 10)
            if previous is not None:  # the camera moves: frames differ, so the comparison can fail
                self.assertGreater(np.abs(actual - previous).max(), 0.05)
            previous = actual

    def test_render_task_runs_blender_itself(self):
        # Any worker, Windows' too, can run the task: its command is the worker's Blender, with no script between
        # (a script would need a shell there). The recorded command lines (the Flamenco test) are Blender's arguments.
        step = next(step for step in self.template(RENDER)["steps"] if step["name"] == "Render")
        self.assertEqual(step["script"]["actions"]["onRun"]["command"], "{{Param.Blender}}")
        self.assertNotIn("embeddedFiles", step["script"])

    def test_worker_without_raysplats_fails_its_task(self):
        env = dict(os.environ, BLENDER_USER_RESOURCES=os.path.join(self.root, "bare_blender"))
        output = os.path.join(self.root, "bare", "frame_####")
        parameters = self.render_parameters(output)
        logs, _ = self.run_on_workers(RENDER, "Render", [{"Frame": "1-2"}], parameters, workers=1, env=env)
        status, log = logs[0]
        self.assertNotEqual(status, 0, log)
        self.assertIn("engine not found 'RAYSPLATS'", log)
        self.assertFalse(os.path.exists(os.path.dirname(output)) and os.listdir(os.path.dirname(output)))

    def test_convert_template_on_two_workers_equals_the_cli(self):
        scans = os.path.join(self.root, "scans")
        os.makedirs(scans)
        for name in CONVERT_INPUTS:
            shutil.copyfile(st.data_file(name), os.path.join(scans, name))
        inputs = sorted(os.path.join(scans, name) for name in os.listdir(scans))
        reference = os.path.join(self.root, "converted_cli")
        ft.run([bpy.app.binary_path, "-b", "-noaudio", "--factory-startup", "--python",
                os.path.join(ft.ADDON_DIR, "raysplats", "cli.py"), "--", "convert", *inputs, "-o", reference,
                "--format", "spz"])

        output = os.path.join(self.root, "converted_farm")
        parameters = {"InputFiles": json.dumps(inputs), "OutputFolder": output, "OutputFormat": "spz",
                      "Blender": bpy.app.binary_path}
        tasks = self.tasks(CONVERT, "Convert", **parameters)
        self.assertEqual(tasks, [{"File": path} for path in inputs])
        logs, _ = self.run_on_workers(CONVERT, "Convert", tasks, parameters)
        for status, log in logs:
            self.assertEqual(status, 0, log)
        self.assertEqual(sorted(os.listdir(output)), sorted(os.listdir(reference)))
        self.assertEqual(len(os.listdir(output)), len(CONVERT_INPUTS))
        for name in os.listdir(reference):
            with open(os.path.join(reference, name), "rb") as a, open(os.path.join(output, name), "rb") as b:
                self.assertTrue(a.read() == b.read(), f"{name}: the job's file differs from the CLI's")

    @unittest.skipUnless(shutil.which("node"), "node is not installed")
    def test_flamenco_tasks_run_the_render_templates_commands(self):
        # Both managers' workers run a recorder in Blender's place, which writes down its command line.
        recorder = os.path.join(self.root, "blender_recorder.py")
        record = os.path.join(self.root, "recorded.jsonl")
        with open(recorder, "w") as out:
            out.write("#!/usr/bin/python3\nimport json, os, sys\n"
                      "open(os.environ['RAYSPLATS_RECORD'], 'a').write(json.dumps(sys.argv) + '\\n')\n")
        os.chmod(recorder, 0o755)
        frames, chunk_size, output = "1-10,20-22", 4, "/renders/shot/frame_####"
        parameters = {"BlendFile": "/shots/shot.blend", "Frames": frames, "ChunkSize": chunk_size,
                      "OutputPath": output, "OutputFormat": "OPEN_EXR", "Threads": 3, "Blender": recorder}
        tasks = self.tasks(RENDER, "Render", **parameters)
        logs, _ = self.run_on_workers(RENDER, "Render", tasks, parameters,
                                      env=dict(self.worker_env, RAYSPLATS_RECORD=record))
        for status, log in logs:
            self.assertEqual(status, 0, log)
        with open(record) as lines:
            openjd_commands = sorted(json.loads(line) for line in lines)

        request = os.path.join(self.root, "flamenco_request.json")
        with open(request, "w") as out:
            json.dump({"settings": {"frames": frames, "chunk_size": chunk_size, "threads": 3,
                                    "render_output_path": output, "format": "OPEN_EXR",
                                    "blendfile": "/shots/shot.blend"},
                       "variables": {"blender": recorder, "blenderArgs": "-b -y"}}, out)
        compiled = json.loads(ft.run(["node", os.path.join(ft.HERE, "flamenco_compile.js"),
                                      os.path.join(ft.FARM, "flamenco", "raysplats_render.js"), request]).stdout)
        flamenco_commands = sorted(command["argv"] for task in compiled["tasks"] for command in task["commands"])
        self.assertEqual(len(openjd_commands), 4)  # 1-10 in 3 chunks, 20-22 in one
        self.assertEqual(flamenco_commands, openjd_commands)
        # The job type offers the template's parameters, with its defaults and choices.
        settings = {setting["key"]: setting for setting in compiled["job_type"]["settings"]}
        template = {parameter["name"]: parameter for parameter in self.template(RENDER)["parameterDefinitions"]}
        pairs = {"BlendFile": "blendfile", "Frames": "frames", "ChunkSize": "chunk_size", "Threads": "threads",
                 "OutputPath": "render_output_path", "OutputFormat": "format"}
        self.assertEqual(set(template) - {"Blender"}, set(pairs))  # Blender: Flamenco's {blender} variable
        self.assertEqual(settings["format"]["choices"], template["OutputFormat"]["allowedValues"])
        for name in ("ChunkSize", "Threads"):
            self.assertEqual(settings[pairs[name]]["default"], template[name]["default"], name)
            self.assertEqual(settings[pairs[name]]["propargs"],
                             {"min": template[name]["minValue"], "max": template[name]["maxValue"]}, name)

# Progress and timing of long operations: Blender's progress indicator plus a per-stage timing line on the
# console, so the slowest stage of an import or export is obvious.
import time


class StageProgress:
    def __init__(self, window_manager, title, stage_count):
        self.window_manager = window_manager
        self.title = title
        self.stage_count = max(1, stage_count)
        self.times = {}
        self._done = 0
        self._stage = None
        self._start = None

    def __enter__(self):
        if self.window_manager is not None:
            self.window_manager.progress_begin(0, self.stage_count)
        return self

    def add_stages(self, count):
        """`count` more stages than announced (e.g. one per piece of a split import): the bar's range grows."""
        self.stage_count += count
        if self.window_manager is not None:
            self.window_manager.progress_begin(0, self.stage_count)
            self.window_manager.progress_update(self._done)

    def stage(self, name):
        """Starts stage `name`; a name used again adds to its time."""
        self._finish_stage()
        self._stage, self._start = name, time.perf_counter()

    def _finish_stage(self):
        if self._stage is not None:
            self.times[self._stage] = self.times.get(self._stage, 0.0) + time.perf_counter() - self._start
            self._done += 1
            if self.window_manager is not None:
                self.window_manager.progress_update(self._done)
            self._stage = None

    def __exit__(self, *exc):
        self._finish_stage()
        if self.window_manager is not None:
            self.window_manager.progress_end()
        return False

    def summary(self):
        total = sum(self.times.values())
        parts = ", ".join(f"{name} {seconds:.2f} s" for name, seconds in self.times.items())
        return f"{self.title}: {parts}; total {total:.2f} s"


class StageClock:
    """Process CPU seconds (every thread's: time.process_time) and wall seconds per named stage, summed over the
    stage's uses; what a frame's benchmark reports (examples/benchmark_frame_cost.py). Stages may nest: each
    counts its own time, the inner stage's included."""

    def __init__(self):
        self.stages = {}  # name -> [cpu seconds, wall seconds]

    def stage(self, name):
        return _ClockedStage(self, name)

    def add(self, name, cpu_seconds, wall_seconds):
        entry = self.stages.setdefault(name, [0.0, 0.0])
        entry[0] += cpu_seconds
        entry[1] += wall_seconds


class _ClockedStage:
    def __init__(self, clock, name):
        self.clock, self.name = clock, name

    def __enter__(self):
        self.cpu, self.wall = time.process_time(), time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.clock.add(self.name, time.process_time() - self.cpu, time.perf_counter() - self.wall)
        return False

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

    def stage(self, name):
        self._finish_stage()
        self._stage, self._start = name, time.perf_counter()

    def _finish_stage(self):
        if self._stage is not None:
            self.times[self._stage] = time.perf_counter() - self._start
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

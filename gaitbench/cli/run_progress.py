"""How ``gaitbench run`` shows its progress: a bar with the walks in flight on a terminal, timestamped lines in a
log (a batch job's output, `nohup`), since a case can take hours and a log cannot redraw a bar."""

from __future__ import annotations

import math
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, ProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.text import Text

from gaitbench.cli.common import count


class StepsInFlight(ProgressColumn):
    """The suite's walks in flight and the steps each has saved (their checkpoints' progress files), read at most
    every 2 s: a case of hours shows how far it is."""

    def __init__(self, store_dir: Path, cases) -> None:
        from gaitbench.run.store import CHECKPOINTS_DIR

        super().__init__()
        self.directory = store_dir / CHECKPOINTS_DIR
        self.labels = {case.key: case.label.split(":")[0] for case in cases}
        self.text, self.read_at = Text(""), -math.inf

    def render(self, task) -> Text:
        from gaitbench.checkpoint import saved_progress

        if time.monotonic() - self.read_at >= 2.0:
            self.read_at = time.monotonic()
            self.text = Text(steps_in_flight(saved_progress(self.directory), self.labels))
        return self.text

    def finished(self, key: str) -> None:
        """The case ``key`` is done: no longer in flight, though a failed walk keeps its checkpoint (for ``--resume``)
        and so its saved steps."""
        self.labels.pop(key, None)
        self.read_at = -math.inf

    def new_steps(self, seen: dict[str, int]) -> list[str]:
        """``step 3 of 11 saved (forward N=140 D&C-DM), 1.25 h`` for each walk of this suite whose saved steps
        changed since ``seen`` (case key → steps saved, updated here; fewer is a walk started again from step 1,
        its checkpoint from other code discarded): a log's view of the walks in flight."""
        from gaitbench.checkpoint import saved_progress

        lines = []
        for key, saved in sorted(saved_progress(self.directory).items()):
            count = saved.get("saved")
            if key in self.labels and isinstance(count, int) and count != seen.get(key, 0):
                seen[key] = count
                lines.append(f"step {count} of {saved.get('of') or '?'} saved ({self.labels[key]}), "
                             f"{duration(saved.get('elapsed_s', 0.0))}")
        return lines


def duration(seconds: float) -> str:
    """``42 s``, ``12.5 min`` or ``3.25 h``: a case's time as a log reader takes it in."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 3600 else f"{seconds / 3600:.2f} h"


def steps_in_flight(progress: dict[str, dict], labels: dict[str, str]) -> str:
    """``in flight: 3 of 11 steps (forward N=140 D&C-DM), ...`` for the walks of ``labels`` (case key → label)
    that have saved steps; empty when none has."""
    walks = [f"{saved['saved']} of {saved.get('of') or '?'} steps ({labels[key]})"
             for key, saved in sorted(progress.items()) if key in labels and "saved" in saved]
    return "in flight: " + ", ".join(walks) if walks else ""


class CaseProgress:
    """Cases done, failed and left, with an estimate of the time left, and the steps the walks in flight have
    saved; each failure printed as it happens.

    Where the output is no terminal (a batch job's log, `nohup`), a bar cannot show: each finished case and each
    step a walk in flight saves (read every :data:`LOG_POLL_S` seconds) is a timestamped line instead."""

    LOG_POLL_S = 30.0

    def __init__(self, console: Console, in_flight: StepsInFlight) -> None:
        self.console = console
        self.in_flight = in_flight
        self.done = self.failed = self.taken = 0
        self.progress = Progress(
            TextColumn("{task.description}"), BarColumn(),
            TextColumn("{task.fields[done]} done · {task.fields[failed]} failed · {task.fields[left]} left"),
            TimeElapsedColumn(), TextColumn("eta"), TimeRemainingColumn(), in_flight, console=console,
            transient=False)
        self.task = None
        self.logging = not console.is_terminal
        self._stop = threading.Event()
        self._watcher: threading.Thread | None = None

    def __enter__(self) -> CaseProgress:
        return self

    def __exit__(self, *exc_info) -> None:
        if self._watcher is not None:
            self._stop.set()
            self._watcher.join()
        if self.task is not None:
            self.progress.__exit__(*exc_info)

    def start(self, to_run: int, skipped: int) -> None:
        """Show the bar once the run has started, so that an error before it (the store) stays one line."""
        self.progress.__enter__()
        if skipped:
            self.console.print(f"{count(skipped, 'case')} already in the store {'is' if skipped == 1 else 'are'} "
                               "skipped")
        self.task = self.progress.add_task("cases", total=to_run, done=0, failed=0, left=to_run)
        if self.logging:
            self.log(f"{count(to_run, 'case')} to run")
            self._watcher = threading.Thread(target=self._log_steps, name="steps-in-flight", daemon=True)
            self._watcher.start()

    def log(self, message: str, style: str | None = None) -> None:
        """One line of a run's log, stamped with the time (UTC)."""
        stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
        self.console.print(Text(f"{stamp} {message}", style=style or ""), soft_wrap=True)

    def _log_steps(self) -> None:
        seen: dict[str, int] = {}
        while True:
            for line in self.in_flight.new_steps(seen):
                self.log(line)
            if self._stop.wait(self.LOG_POLL_S):
                return

    def elsewhere(self, case) -> None:
        """A case another run sharing the store took: no longer left for this one."""
        self.taken += 1
        total = self.progress.tasks[0].total or 0
        self.progress.update(self.task, advance=1, left=int(total) - self.done - self.taken)

    def advance(self, outcome) -> None:
        self.done += 1
        self.in_flight.finished(outcome.case.key)
        total = self.progress.tasks[0].total or 0
        if outcome.failed:
            self.failed += 1
            failure = f"{outcome.status}: {outcome.case.label}: {outcome.message}"
            if self.logging:
                self.log(f"[{self.done}/{int(total)}] {failure}", style="yellow")
            else:
                self.console.print(Text(failure, style="yellow"), soft_wrap=True)
        elif self.logging:
            acot = outcome.metrics.get("acot")
            self.log(f"[{self.done}/{int(total)}] solved: {outcome.case.label}: ACOT "
                     f"{'none' if acot is None else format(acot, '.4f')}, {duration(outcome.wall_time_s)}")
        self.progress.update(self.task, advance=1, done=self.done, failed=self.failed,
                             left=int(total) - self.done - self.taken)

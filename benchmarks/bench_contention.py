"""Why a campaign run costs more CPU when two run at once (issue 26): the runs' own figures, and the machine's.

Part 1, the runs: ``--runs`` campaign runs (bench_campaign's: 2 s tool change, monitor, LS + IV) in one worker
process alone, then in two workers at once, for ``--rounds`` rounds. Each worker is forked from this process once
the run's imports are done and runs them as a pool worker does (``runner.execute``: each run forked from the
worker, its children reaped before the next). Per run: CPU time (user and system, the worker's and its runs'),
minor page faults, voluntary and involuntary context switches (``getrusage``); the least CPU of the rounds is
printed, and the ratio two-at-once / alone. Equal faults and switches with more CPU say the loss is not the runs'
doing (more work, more faults, more waiting) but each instruction taking longer: the hardware shared by the two.

Part 2, the machine's ceiling (needs ``cc``): C loops of fixed work, timed alone and two at once (CPU time of the
loop only, not its set-up): ``alu`` (a floating-point chain in registers), ``chase 512 KiB`` / ``chase 8 MiB`` (a
pointer chase through a random cycle: every load waits for the last one, a working set in the core's L2 / in the
shared L3), ``stream 8 MiB`` / ``stream 64 MiB`` (sequential read-modify-write, prefetched), ``faults`` (64 MiB
mapped, one write a page, unmapped). Their ratios bound what software can do: a loss that a pure C loop of the
same kind shows too is the machine's (its caches, its memory, the host's other tenants), not the runs'.

On a shared machine "alone" means "beside whatever else runs": the best of several rounds is printed, and the
load average before each part.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_contention.py [--runs 4] [--rounds 3] [--no-runs] [--no-c]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

FIELDS = ("ru_utime", "ru_stime", "ru_minflt", "ru_nvcsw", "ru_nivcsw")

C_SOURCE = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <sys/mman.h>
static double cpu(void) { struct timespec t; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static volatile double sink;
static double alu(long n) { double t = cpu(), a = 1.0, b = 1.0000001;
  for (long i = 0; i < n; i++) { a = a * b + 1e-9; b = b * 0.9999999 + 1e-7; } sink = a + b; return cpu() - t; }
static double chase(size_t bytes, long passes) { size_t n = bytes / sizeof(size_t), k = 0;
  size_t *p = malloc(n * sizeof *p), *q = malloc(n * sizeof *q); unsigned long long s = 88172645463325252ULL;
  for (size_t i = 0; i < n; i++) p[i] = i;
  for (size_t i = n - 1; i > 0; i--) { s ^= s << 13; s ^= s >> 7; s ^= s << 17; size_t j = s % (i + 1), t = p[i]; p[i] = p[j]; p[j] = t; }
  for (size_t i = 0; i < n; i++) q[p[i]] = p[(i + 1) % n];
  double t = cpu(); for (long r = 0; r < passes; r++) for (size_t i = 0; i < n; i++) k = q[k];
  t = cpu() - t; sink = (double)k; free(p); free(q); return t; }
static double stream(size_t bytes, long passes) { size_t n = bytes / 8; double *a = malloc(bytes);
  for (size_t i = 0; i < n; i++) a[i] = (double)i;
  double t = cpu(); for (long r = 0; r < passes; r++) for (size_t i = 0; i < n; i++) a[i] = a[i] * 1.0000001 + 1.0;
  t = cpu() - t; sink = a[n / 2]; free(a); return t; }
static double faults(size_t bytes, long reps) { double t = cpu();
  for (long r = 0; r < reps; r++) { char *m = mmap(0, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    for (size_t i = 0; i < bytes; i += 4096) m[i] = 1; munmap(m, bytes); }
  return cpu() - t; }
int main(int argc, char **argv) { const char *k = argc > 1 ? argv[1] : ""; double t = -1;
  if (!strcmp(k, "alu")) t = alu(150000000L);
  else if (!strcmp(k, "chase-512k")) t = chase(512 << 10, 1500);
  else if (!strcmp(k, "chase-8m")) t = chase(8 << 20, 8);
  else if (!strcmp(k, "stream-8m")) t = stream(8 << 20, 150);
  else if (!strcmp(k, "stream-64m")) t = stream(64 << 20, 15);
  else if (!strcmp(k, "faults")) t = faults(64 << 20, 25);
  printf("%.6f\n", t); return t < 0; }
"""
KINDS = ("alu", "chase-512k", "chase-8m", "stream-8m", "stream-64m", "faults")


def _usage() -> dict[str, float]:
    """This process's and its reaped children's resource usage, summed."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return {f: getattr(own, f) + getattr(children, f) for f in FIELDS}


def _worker(specs: list, fd: int) -> None:  # pragma: no cover - a forked worker
    """``len(specs)`` runs as a pool worker runs them; their usage per run, as JSON, to ``fd``."""
    from feeddrive.cosim import supervise
    from feeddrive.cosim.campaign.cosim_run import run_cosim
    from feeddrive.cosim.campaign.runner import execute

    supervise.REAP_IN_THREAD = False
    before = _usage()
    for spec in specs:
        record = execute(run_cosim, spec)
        if record["status"] != "ok":
            os.write(fd, json.dumps({"error": record["reason"]}).encode())
            os._exit(1)
    supervise.reap(block=True)
    after = _usage()
    os.write(fd, json.dumps({f: (after[f] - before[f]) / len(specs) for f in FIELDS}).encode())
    os._exit(0)


def _together(groups: list[list]) -> list[dict[str, float]]:
    """One forked worker per group of specs, all at once; each one's usage per run."""
    pipes = []
    for specs in groups:
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the worker
            os.close(read)
            _worker(specs, write)
        os.close(write)
        pipes.append((pid, read))
    out = []
    for pid, read in pipes:
        with os.fdopen(read) as f:
            out.append(json.loads(f.read() or '{"error": "the worker died"}'))
        os.waitpid(pid, 0)
    for usage in out:
        if "error" in usage:
            raise SystemExit(f"a run failed: {usage['error']}")
    return out


def runs_part(runs: int, rounds: int) -> None:
    """Per-run CPU, faults and switches of campaign runs: one worker alone, two at once."""
    from bench_campaign import BASE

    from feeddrive.cosim.campaign import Campaign, expand
    from feeddrive.cosim.campaign.cosim_run import run_cosim
    from feeddrive.fmu_build import builtin_fmu

    builtin_fmu()
    run_cosim.prepare()
    campaign = Campaign(name="bench", base=BASE, seed=1, repetitions=max(2 * runs, 2),
                        sweep={"plant.parameters.Cd": [1.3]}, run_options={"methods": ["ls", "iv"]})
    specs = expand(campaign)
    for spec in specs:  # resolved here, inherited by the workers (as a campaign's pool workers)
        run_cosim.validate(spec)
    _together([specs[:1]])  # one-time costs (first imports of a run) outside the rounds
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; {runs} runs a worker, best of {rounds} rounds")
    best: dict[str, dict] = {}
    for _ in range(rounds):
        for mode, groups in (("alone", [specs[:runs]]), ("two at once", [specs[:runs], specs[runs:2 * runs]])):
            for usage in _together(groups):
                cpu = usage["ru_utime"] + usage["ru_stime"]
                if mode not in best or cpu < best[mode]["ru_utime"] + best[mode]["ru_stime"]:
                    best[mode] = usage
    print(f"{'a run':12} {'CPU ms':>7} {'user':>6} {'system':>7} {'faults':>7} {'vol. sw':>8} {'invol. sw':>10}")
    for mode, u in best.items():
        print(f"{mode:12} {1e3 * (u['ru_utime'] + u['ru_stime']):7.0f} {1e3 * u['ru_utime']:6.0f} "
              f"{1e3 * u['ru_stime']:7.0f} {u['ru_minflt']:7.0f} {u['ru_nvcsw']:8.0f} {u['ru_nivcsw']:10.0f}")
    a, b = best["alone"], best["two at once"]
    ratio = {f: b[f] / a[f] if a[f] else float("nan") for f in FIELDS}
    print(f"{'ratio':12} {(b['ru_utime'] + b['ru_stime']) / (a['ru_utime'] + a['ru_stime']):7.2f} "
          f"{ratio['ru_utime']:6.2f} {ratio['ru_stime']:7.2f} {ratio['ru_minflt']:7.2f} {ratio['ru_nvcsw']:8.2f} "
          f"{ratio['ru_nivcsw']:10.2f}")


def ceiling_part(rounds: int) -> None:
    """CPU time of fixed C loops alone and two at once: the machine's own ratio for each kind of work."""
    cc = shutil.which(os.environ.get("CC") or "cc")
    if cc is None:
        print("the machine's ceiling: no C compiler (cc or $CC) found, skipped")
        return
    with tempfile.TemporaryDirectory() as tmp:
        source, program = Path(tmp, "ceiling.c"), Path(tmp, "ceiling")
        source.write_text(C_SOURCE)
        subprocess.run([cc, "-O2", "-o", str(program), str(source)], check=True)
        print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; C loops, best of {rounds} rounds")
        print(f"{'work':12} {'alone s':>8} {'two at once s':>14} {'ratio':>6}")
        for kind in KINDS:
            alone, pair = [], []
            for _ in range(rounds):
                alone.append(float(subprocess.run([program, kind], capture_output=True, text=True, check=True).stdout))
                procs = [subprocess.Popen([program, kind], stdout=subprocess.PIPE, text=True) for _ in range(2)]
                pair.append(sum(float(p.communicate()[0]) for p in procs) / 2)
            print(f"{kind:12} {min(alone):8.3f} {min(pair):14.3f} {min(pair) / min(alone):6.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=4, help="runs a worker in each round")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of each part; the best is printed")
    parser.add_argument("--no-runs", action="store_true", help="skip the campaign runs")
    parser.add_argument("--no-c", action="store_true", help="skip the C loops")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if not args.no_runs:
        runs_part(args.runs, args.rounds)
    if not args.no_c:
        ceiling_part(args.rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())

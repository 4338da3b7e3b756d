"""The master's fast path: the ticks between two Python steps in one call of the compiled loop.

``Master.run`` calls :func:`run_blocks` for each stretch of ``Master.block`` recording steps. A block runs
from one tick to the next at which a component stepping in Python steps (before the block: those placed
before the plant, e.g. the NC when the compiled loop does not step it; at its last tick: those after the
sensors, e.g. a user component), or an event lands. The components the compiled loop steps itself
(``FineLoop.absorbed``: the NC, the monitor's buffering of a motion) do not end a block; the monitor still
steps in Python at a block's last tick, and the compiled loop ends a block early at a tick where the
monitor's step does more than buffer a sample (a motion starts or ends, the request's age is reached).
"""
from __future__ import annotations

import math
from typing import Any

from feeddrive.cosim.fastloop import servo as servo_loop


def tables(master: Any, fine: Any, schedule: list[list[tuple]], period: int) -> tuple:
    """Per tick residue modulo ``P = lcm(period, m)``: the Python entries before the plant and after the
    sensors, whether a row is recorded, and the ticks from there to the end of the block (a tick after which
    a Python component steps, or before one at which a Python component steps; a whole stretch when none)."""
    names = list(master.components)
    i_plant, i_sensors = names.index("plant"), names.index("sensors")
    order = {c: j for j, c in enumerate(master.components.values())}
    P = math.lcm(period, master.m)
    absorbed = fine.absorbed
    pre = [[x for x in schedule[r % period] if order[x[0]] < i_plant and x[0] not in absorbed] for r in range(P)]
    # the servo sensors step in the compiled loop at every tick of theirs: not in Python at a block's end
    post = [[x for x in schedule[r % period] if order[x[0]] > i_sensors and x[0] is not fine.servo] for r in range(P)]
    is_rec = [master.m == 1 or (r + 1) % master.m == 0 for r in range(P)]
    ends = [any(x[0] not in absorbed for x in post[t]) or bool(pre[(t + 1) % P]) for t in range(P)]
    span = [master.block * master.m] * P  # nothing in Python: blocks of a whole stretch
    if any(ends):
        nxt = next(t for t in range(P) if ends[t]) + P  # the first end, one period later
        for r in range(P - 1, -1, -1):
            nxt = r if ends[r] else nxt
            span[r] = nxt - r + 1
    return pre, post, is_rec, span, P


def run_blocks(master: Any, fine: Any, fast: tuple, k: int, k1: int, Y: list, rows: list, e: int,
               next_event: int, where: list) -> tuple[int, int]:
    """Ticks k .. k1 - 1 with the plant and the sensors (and what ``fine`` absorbed) in compiled blocks;
    returns the events' state. On a failure ``where`` gets the tick and the component (for the error)."""
    pre, post, is_rec, span, P = fast
    recorder, components = master.recorder, master.components
    events, rec = master._events, master._rec_get
    plant, sensors, servo, s = fine.plant, fine.sensors, fine.servo, fine.s
    set_plant, get_plant = plant.set_inputs, master._getters[list(components).index("plant")]
    run, out, a, b = fine.run, fine.out, fine.a, fine.b
    nc = fine.nc
    flush = fine.flush_monitor if fine.monitor is not None else None
    c = None
    try:
        while k < k1:
            if k == next_event:
                plant._k = k  # the time of an event's failure (FMUComponent._raise)
                while k == next_event:
                    _, name, param, value = events[e]
                    c = components[name]
                    c.set_parameter(param, value)
                    if c is sensors:
                        fine.noise_changed()
                    elif c is servo:
                        servo_loop.changed(fine, servo)
                    e += 1
                    next_event = events[e][0] if e < len(events) else -1
            r = k % P
            for c, set_inputs, getter, step, get_outputs, ya, yb, d in pre[r]:
                set_inputs(getter(Y))
                step(k // d)
                Y[ya:yb] = get_outputs()
            n = span[r]
            if k + n > k1:
                n = k1 - k
            if k < next_event < k + n:
                n = next_event - k
            c = plant
            set_plant(get_plant(Y))
            k = run(k, n, Y)
            if s.rec_rows:
                fine.take_rows(Y, rows, recorder)
            Y[a:b] = out[:]
            if nc is not None:  # the NC's state and motion as the ints it gives
                Y[a + 5], Y[a + 6] = int(Y[a + 5]), int(Y[a + 6])
            if flush is not None:
                flush()
            r = (k - 1) % P
            for c, set_inputs, getter, step, get_outputs, ya, yb, d in post[r]:
                set_inputs(getter(Y))
                step((k - 1) // d)
                Y[ya:yb] = get_outputs()
            if is_rec[r]:
                rows.append(rec(Y))
    except BaseException:
        where[:] = [k, c]
        if s.rec_rows:  # the rows recorded in the block before its failure
            fine.take_rows(Y, rows, recorder)
        if flush is not None:
            flush()
        raise
    return e, next_event

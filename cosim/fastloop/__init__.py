"""The co-simulation's fine loop in compiled code: the plant FMU and the sensors stepped in blocks.

The master (cosim/master.py) steps the plant and the sensors at every tick of the finest step; the NC,
the monitor and the user components at their own rates. Between two ticks at which a Python component
steps or an event lands (cosim/fastloop/blocks.py), the standard NC (its plan, position loop and motion
count; the steps that insert an identification motion go back to Python), the plant (fmi2SetReal,
fmi2SetRealInputDerivatives, fmi2DoStep, fmi2GetReal through the FMU's own function pointers), the sensors (interval means, low-pass filters,
noise, encoder), a PMSM's servo sensors (cosim/fastloop/servo.py) and the monitor's buffering of a motion's samples (it stops the block where the monitor's
step does more) run in ``fineloop.c`` without the interpreter, with the same arithmetic in the same order,
and the rows recorded inside the block go to a preallocated array (the master fills in the columns of
the Python components, constant over the block, and takes the block's last row itself): the results are
bit-identical to the Python loop's (tests/cosim/test_fastloop.py).

Which runs take it: see :func:`cosim.fastloop.fine.plan`; ``Master.loop`` says which loop ran and why.
"""
from feeddrive.cosim.fastloop.fine import FineLoop, plan

__all__ = ["FineLoop", "plan"]

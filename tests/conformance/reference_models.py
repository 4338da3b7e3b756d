"""Where the Modelica Reference-FMUs' source is and which models each FMI version builds (shared by the
conformance fixture and tests)."""
from __future__ import annotations

from pathlib import Path

SOURCE = Path(__file__).resolve().parents[2] / ".." / "shared" / "third_party" / "Reference-FMUs"
#: the models each FMI version builds (FMI 2.0: six; FMI 3.0: all of them and Clocks)
MODELS = {2: ("BouncingBall", "Dahlquist", "Feedthrough", "Resource", "Stair", "VanDerPol"),
          3: ("BouncingBall", "Dahlquist", "Feedthrough", "Resource", "Stair", "VanDerPol", "StateSpace",
              "Roberts", "Clocks")}

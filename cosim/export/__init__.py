"""The project's components as FMUs and a scenario as an OSP system, for other co-simulation masters.

* ``slave.py``   pythonfmu slave classes running the NC, the sensors and the monitor (FMI 2.0 CS)
* ``build.py``   ``build_component_fmu``: one component of a scenario -> .fmu (pythonfmu's builder)
* ``system.py``  ``export_system``: the FMUs, the plant FMU, OspSystemStructure.xml, an OSP scenario
                 file for the timed events and an SSP archive
* ``libcosim.py`` ``run_osp`` / ``run_osp_isolated``: an exported system run by OSP libcosim (libcosimpy)
"""

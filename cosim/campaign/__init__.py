"""Campaigns: many co-simulations of one base scenario, with swept and drawn changes, and their statistics.

The parts, in the order a campaign uses them:

- :mod:`.schema`: the campaign file (``load_campaign``) and its expansion into runs (``expand``);
- :mod:`.execute`: running them in this process, on a local pool or on Dask, into a resumable store
  (``run_campaign``);
- :mod:`.runner`: one run, supervised in a forked child, and its record (``execute``);
- :mod:`.cluster`: a local Dask cluster whose workers are forked warm (``local_cluster``);
- :mod:`.zygote`: the single-threaded processes a ``local_cluster``'s runs are forked from;
- :mod:`.cosim_run`: the default run function, one co-simulation with its monitor (``run_cosim``);
- :mod:`.aggregate`: detection and estimation tables and plots (``aggregate``).

See :mod:`.schema` for the file format and the run-function protocol.
"""
from feeddrive.cosim.campaign.aggregate import Aggregates, aggregate, fault_class, plot_campaign, plot_drift
from feeddrive.cosim.campaign.cluster import local_cluster
from feeddrive.cosim.campaign.cosim_run import run_cosim
from feeddrive.cosim.campaign.execute import CampaignResult, execute, resolve_function, run_campaign
from feeddrive.cosim.campaign.schema import Campaign, CampaignError, RunSpec, expand, load_campaign, parse_key, set_key

__all__ = ["Aggregates", "Campaign", "CampaignError", "CampaignResult", "RunSpec", "aggregate", "execute", "expand",
           "fault_class", "load_campaign", "local_cluster", "parse_key", "plot_campaign", "plot_drift", "resolve_function",
           "run_campaign", "run_cosim", "set_key"]

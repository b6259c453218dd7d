"""Built-in candidate fitters: by simulation (paper 000) and by full discretisation (paper 004)."""
from mcl import hookimpl
from mcl.discovery.fitters import FullDiscretisationFitter, SimulationFitter


@hookimpl
def mcl_fitters():
    return [SimulationFitter, FullDiscretisationFitter]

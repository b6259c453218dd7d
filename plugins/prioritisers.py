"""Built-in prioritisers for backward elimination: all at once, highest degree first."""
from pipeline import hookimpl
from pipeline.sparsify import AllAtOnce, HighestDegreeFirst


@hookimpl
def mcl_prioritisers():
    return [HighestDegreeFirst, AllAtOnce]

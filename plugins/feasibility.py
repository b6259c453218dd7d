"""Built-in feasibility models: logistic (paper 000's "softmax") and a small neural network."""
from mcl import hookimpl
from mcl.feasibility import LogisticFeasibility, NeuralFeasibility


@hookimpl
def mcl_feasibility_models():
    return [LogisticFeasibility, NeuralFeasibility]

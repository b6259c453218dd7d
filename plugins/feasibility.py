"""Built-in feasibility models: logistic (paper 000's "softmax") and a small neural network."""
from pipeline import hookimpl
from pipeline.feasibility import LogisticFeasibility, NeuralFeasibility


@hookimpl
def mcl_feasibility_models():
    return [LogisticFeasibility, NeuralFeasibility]

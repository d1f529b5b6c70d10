"""Subprocess body for the kill-and-resume test: trains a small DRF until killed or done."""
import sys

import torch

from tests.test_train import tiny_data, CONFIG_KIND, train_cfg
from drfkit.study.studies import model_config
from drfkit.methods.train import train_model

if __name__ == "__main__":
    torch.set_num_threads(1)
    train, val = tiny_data()
    train_model(model_config("pendulum", CONFIG_KIND), train, val, train_cfg(epochs=int(sys.argv[2])),
                sys.argv[1], progress=False)

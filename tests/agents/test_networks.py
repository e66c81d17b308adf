"""The MLP torso's fast forward (its layers called as functions on cached parameter tensors) is
its Sequential's forward, and stays so after the moves and loads that touch the parameters."""

from __future__ import annotations

import copy

import torch

from farsighter.networks import MLPTorso


def test_mlp_body_is_its_sequential_through_moves_loads_and_copies() -> None:
    torch.manual_seed(0)
    torso, x = MLPTorso(4, (16, 8)), torch.randn(5, 4)
    assert torch.equal(torso(x), torso.net(x))
    other = MLPTorso(4, (16, 8))
    other.load_state_dict(torso.state_dict())  # in place: the cached tensors see it
    assert torch.equal(other(x), torso.net(x))
    with torch.no_grad():
        torso.net[0].weight.add_(1.0)  # an optimizer's in-place step
    assert torch.equal(torso(x), torso.net(x))
    twin = copy.deepcopy(torso)  # the target network: its own tensors
    with torch.no_grad():
        twin.net[2].bias.add_(1.0)
    assert torch.equal(twin(x), twin.net(x)) and not torch.equal(twin(x), torso(x))
    # a move that replaces the parameter tensors (torch's overwrite-on-conversion mode): the
    # cache takes the new ones
    torch.__future__.set_overwrite_module_params_on_conversion(True)
    try:
        before = torso.net[0].weight
        torso.double().float()
    finally:
        torch.__future__.set_overwrite_module_params_on_conversion(False)
    assert torso.net[0].weight is not before
    assert torso._params[0][0] is torso.net[0].weight
    with torch.no_grad():
        torso.net[0].weight.add_(1.0)
    assert torch.equal(torso(x), torso.net(x))

"""Activation checkpointing of the branches: the same loss, gradients and BatchNorm statistics as
without; the optimiser of our trainer and the authors' reference step; the option's plumbing."""

from __future__ import annotations

import copy

import pytest
import torch
from click.testing import CliRunner

import semattnet
from semattnet.cli import main
from semattnet.training.checkpointing import BranchCheckpointing, set_activation_checkpointing
from semattnet.training.config import TrainConfig
from semattnet.training.losses import semattnet_loss
from semattnet.training.reference import authors_adam, authors_step, make_adam, our_step
from tests._helpers import random_inputs


def _model() -> torch.nn.Module:
    torch.manual_seed(0)
    return semattnet.build_model("semattnet", width=0.125, iterations=2).train()


def _loss_and_grads(net: torch.nn.Module, x: dict[str, torch.Tensor], gt: torch.Tensor):  # type: ignore[no-untyped-def]
    loss = semattnet_loss(net(**x), gt, 0.1)
    loss.backward()
    return loss.detach(), {n: p.grad.clone() for n, p in net.named_parameters() if p.grad is not None}


def test_checkpointing_keeps_loss_gradients_and_bn_statistics() -> None:
    plain = _model()
    ckpt = copy.deepcopy(plain)
    assert set_activation_checkpointing(ckpt) == 3  # the three branches
    assert set_activation_checkpointing(ckpt) == 0  # already on
    x = random_inputs(b=2, h=32, w=64)
    gt = torch.rand(2, 1, 32, 64) * 80 * (torch.rand(2, 1, 32, 64) < 0.3)
    loss_a, grads_a = _loss_and_grads(plain, x, gt)
    loss_b, grads_b = _loss_and_grads(ckpt, x, gt)
    torch.testing.assert_close(loss_b, loss_a, rtol=1e-6, atol=0)
    assert grads_a.keys() == grads_b.keys() and len(grads_a) > 100
    for name, g in grads_a.items():
        torch.testing.assert_close(grads_b[name], g, rtol=1e-5, atol=1e-7, msg=name)
    for (name, a), b in zip(plain.named_buffers(), ckpt.buffers(), strict=True):  # running stats updated once
        torch.testing.assert_close(b, a, rtol=1e-6, atol=1e-8, msg=name)


def test_checkpointing_is_inert_outside_training_and_can_be_undone() -> None:
    net = _model()
    set_activation_checkpointing(net)
    assert isinstance(net.backbone.branch_runner, BranchCheckpointing)
    net.eval().propagation_impl = "pytorch"  # (not the fused kernel: no compilation here)
    with torch.no_grad():  # no checkpoint without autograd (it would warn and do nothing useful)
        net(**random_inputs(b=1, h=32, w=64))
    assert set_activation_checkpointing(net, False) == 3
    assert net.backbone.branch_runner is None


def test_the_branch_runner_hook_sees_every_branch_and_is_not_replaced() -> None:
    net = _model()
    seen: list[str] = []

    def runner(branch, *inputs):  # type: ignore[no-untyped-def]
        seen.append(branch.__name__)
        return branch(*inputs)

    net.backbone.branch_runner = runner
    net.eval().propagation_impl = "pytorch"
    with torch.no_grad():
        net(**random_inputs(b=1, h=32, w=64))
    assert seen == ["_color_guided", "_semantic_guided", "_depth_guided"]
    with pytest.raises(semattnet.SemAttNetError, match="already has a branch_runner"):
        set_activation_checkpointing(net)


def test_our_step_and_the_authors_step_compute_the_same_loss() -> None:
    a, b = _model(), _model()
    batch = random_inputs(b=1, h=32, w=64)
    batch["gt"] = torch.rand(1, 1, 32, 64) * 80
    dev = torch.device("cpu")
    ours = our_step(a, make_adam(a.parameters(), dev, lr=1e-3), batch, dev)
    theirs = authors_step(b, authors_adam(b.parameters(), lr=1e-3), batch, dev)
    assert float(ours) == pytest.approx(theirs, rel=1e-5)
    grads = [(pa.grad, pb.grad) for pa, pb in zip(a.parameters(), b.parameters(), strict=True) if pa.grad is not None]
    assert len(grads) > 100
    for ga, gb in grads:  # the same gradients (naive against shifted propagation: float rounding)
        torch.testing.assert_close(ga, gb, rtol=1e-3, atol=1e-5 * float(gb.abs().max()) + 1e-9)
    assert b.propagation_impl == "auto"  # restored after the naive step


def test_make_adam_is_fused_or_foreach() -> None:
    opt = make_adam([torch.nn.Parameter(torch.zeros(3))], torch.device("cpu"), lr=1e-3)
    group = opt.param_groups[0]
    assert group["fused"] or group["foreach"]


def test_config_field_and_cli_option() -> None:
    assert TrainConfig().activation_checkpointing is False
    assert TrainConfig(activation_checkpointing=True).to_dict()["activation_checkpointing"] is True
    with pytest.raises(ValueError, match="activation_checkpointing"):
        TrainConfig(activation_checkpointing="yes")  # type: ignore[arg-type]
    result = CliRunner().invoke(main, ["train", "--help"])
    assert "--activation-checkpointing" in result.output

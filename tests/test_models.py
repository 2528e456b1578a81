"""The four models: the paper's parameter counts, 8x8 and cropped input, eval determinism, learning, FLOPs."""

import pytest
import torch
from torch import nn

from denali_pipe.train.cells import TASKS
from denali_pipe.train.models import PAPER_MODELS, cnn1d, forward_flops, n_params, transformer
from denali_pipe.train.registry import n_outputs

# Table 10 of the paper for 3x3x128 input, as rebuilt in REFERENCE Part 2 §2. The one
# exception is the Transformer size model: the reference builds it as a classifier,
# whose head has a LayerNorm(256) (+512 parameters) that the regressor lacks; the
# paper prints 3,228,802, the regressor's count, probably copied from the location
# row. The size checkpoint is not released, so the faithful rebuild's count is asserted.
PAPER_PARAMS = {
    "cnn1d": {"location": 82_340, "shape": 83_198, "size": 82_274},
    "cnn3d": {"location": 2_226_146, "shape": 2_344_158, "size": 2_226_146},
    "mlp": {"location": 754_818, "shape": 758_430, "size": 754_818},
    "transformer": {"location": 3_228_802, "shape": 3_232_926, "size": 3_228_802},
}
REBUILD_PARAMS = {**PAPER_PARAMS, "transformer": {**PAPER_PARAMS["transformer"], "size": 3_229_314}}
CELLS = [(name, task) for name in PAPER_MODELS for task in TASKS]


def build_model(name, task, n, bins, n_classes):
    return PAPER_MODELS[name](task, n_outputs(task, n_classes), (n, n, bins))


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """Batches here are tiny: one thread is as fast, and it does not slow to a crawl
    in OpenMP spin-waits when other jobs keep the cores busy (5x seen on 2 cores)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.mark.parametrize("name, task", CELLS)
def test_parameter_counts_3x3(name, task):
    assert n_params(build_model(name, task, n=3, bins=128, n_classes=30)) == REBUILD_PARAMS[name][task]


def test_transformer_size_differs_from_paper_by_head_layernorm():
    model = transformer("size", 2, (3, 3, 128))
    head_norm = model.head[0]
    assert isinstance(head_norm, nn.LayerNorm)
    assert n_params(model) - n_params(head_norm) == PAPER_PARAMS["transformer"]["size"]


def test_cnn1d_location_dead_out_tanh_is_counted_and_never_used():
    model = cnn1d("location", 2, (3, 3, 128))
    assert n_params(model) - n_params(model.out_tanh) == PAPER_PARAMS["cnn1d"]["size"]
    model(torch.randn(4, 3, 3, 128)).sum().backward()
    assert model.out_tanh.weight.grad is None


def test_an_unknown_task_raises():
    with pytest.raises(ValueError, match="unknown task 'object'"):
        build_model("mlp", "object", n=3, bins=128, n_classes=30)


def test_forward_flops_of_the_mlp_are_its_matrix_products():
    # 2 FLOPs per multiply-add of each Linear layer: 1152 -> 512 -> 256 -> 128 -> 2
    widths = [3 * 3 * 128, 512, 256, 128, 2]
    model = build_model("mlp", "location", n=3, bins=128, n_classes=30).train()
    assert forward_flops(model, (3, 3, 128)) == sum(2 * a * b for a, b in zip(widths, widths[1:]))


def test_forward_flops_see_the_transformers_encoder_and_leave_the_model_alone():
    """Every token passes every encoder weight matrix once: at least 2 FLOPs per weight and token."""
    model = transformer("location", 2, (3, 3, 57)).eval()
    weights = sum(p.numel() for name, p in model.encoder.named_parameters() if p.dim() == 2)
    assert forward_flops(model, (3, 3, 57)) > 2 * weights * 58  # 57 time-bin tokens and the CLS token
    net = cnn1d("size", 2, (3, 3, 57)).eval()
    before = {k: v.clone() for k, v in net.state_dict().items()}
    forward_flops(net, (3, 3, 57))
    assert not net.training and all(torch.equal(before[k], v) for k, v in net.state_dict().items())


# 8x8 zones with a cropped time axis, and the paper's full 3x3x128 input.
@pytest.mark.parametrize("n, bins", [(8, 56), (3, 128)])
@pytest.mark.parametrize("name, task", CELLS)
def test_forward_backward_shapes_and_eval_determinism(name, task, n, bins):
    torch.manual_seed(0)
    n_out = {"location": 2, "shape": 9, "size": 2}[task]
    model = build_model(name, task, n=n, bins=bins, n_classes=9)
    x = torch.randn(2, n, n, bins)
    y = model(x)
    assert y.shape == (2, n_out)
    y.square().sum().backward()
    grads = [p.grad for name_, p in model.named_parameters() if not name_.startswith("out_tanh")]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    model.eval()
    with torch.no_grad():
        assert torch.equal(model(x), model(x))


def test_cnn1d_learns_two_separable_classes():
    """A sanity check that training works end to end: a peak early or late in time."""
    torch.manual_seed(0)
    n, bins, per_class = 3, 32, 8
    x = torch.rand(2 * per_class, n, n, bins)
    x[:per_class, :, :, 4:8] += 3.0
    x[per_class:, :, :, 20:24] += 3.0
    y = torch.arange(2).repeat_interleave(per_class)
    model = cnn1d("size", 2, (n, n, bins))
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss_fn = nn.CrossEntropyLoss()
    losses = []
    for _ in range(30):
        opt.zero_grad()
        loss = loss_fn(model(x), y)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    model.eval()
    with torch.no_grad():
        assert (model(x).argmax(1) == y).all()
    assert losses[-1] < 0.5 * losses[0]

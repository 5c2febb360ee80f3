"""The T-SCvx networks f2 (tight rows) and f1 (solution) and the predictor the solver calls."""

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed: the networks are untested")

from scpformer.models.tscvx import (  # noqa: E402
    SOLUTION_KIND,
    TIGHT_KIND,
    TOKENIZATIONS,
    SolutionConfig,
    SolutionRegressor,
    TightClassifier,
    TightConfig,
    TscvxNormalization,
    TscvxPredictor,
    build_model,
    config_from_dict,
    iteration_feature,
    preset,
)

N = 5  # nodes of the small test networks


def tiny(kind, tokens="single"):
    torch.manual_seed(0)
    sizes = dict(d_model=16, n_head=2, n_layer=1, d_ff=32, dropout=0.0, tokens=tokens, n_nodes=N)
    if kind == TIGHT_KIND:
        return TightClassifier(TightConfig(**sizes, iter_max=10))
    return SolutionRegressor(SolutionConfig(**sizes))


def normalization(seed=0):
    rng = np.random.default_rng(seed)
    return TscvxNormalization(
        theta_mean=rng.normal(size=16), theta_std=rng.uniform(0.5, 2.0, 16),
        x_mean=rng.normal(size=(N, 14)), x_std=rng.uniform(0.5, 2.0, (N, 14)),
        u_mean=rng.normal(size=(N, 3)), u_std=rng.uniform(0.5, 2.0, (N, 3)),
        tf_mean=3.0, tf_std=0.5,
    )  # fmt: skip


@pytest.fixture
def predictor():
    return TscvxPredictor(tiny(TIGHT_KIND), tiny(SOLUTION_KIND), normalization())


@pytest.mark.parametrize("tokens", TOKENIZATIONS)
def test_classifier_gives_one_logit_per_name_and_node(tokens):
    net = tiny(TIGHT_KIND, tokens)
    logits = net(torch.randn(3, 16), torch.tensor([1, 4, 10]))
    assert logits.shape == (3, 7 * N)


@pytest.mark.parametrize("tokens", TOKENIZATIONS)
def test_regressor_gives_x_u_and_final_time(tokens):
    out = tiny(SOLUTION_KIND, tokens)(torch.randn(2, 16))
    assert out.shape == (2, 17 * N + 1)


def test_the_iteration_changes_the_classifier_output():
    net = tiny(TIGHT_KIND).eval()
    theta = torch.randn(1, 16)
    assert not torch.allclose(net(theta, torch.tensor([1])), net(theta, torch.tensor([9])))


def test_iteration_feature_spans_minus_one_to_one():
    assert iteration_feature(torch.tensor([1, 10]), 10).tolist() == [-1.0, 1.0]


def test_paper_classifier_has_table3_size():
    net = build_model(TIGHT_KIND, preset(TIGHT_KIND, "paper"))
    params = sum(p.numel() for p in net.parameters())
    assert 8.7e6 < params < 8.95e6  # Table 3: 8.91 M with 12 N outputs, ours 7 N


def test_presets_hold_the_papers_sizes():
    tight, solution = preset(TIGHT_KIND, "paper"), preset(SOLUTION_KIND, "paper")
    assert (tight.d_model, tight.n_head, tight.n_layer, tight.dropout) == (384, 2, 4, 0.1)
    assert (solution.d_model, solution.n_head, solution.n_layer) == (768, 2, 4)
    assert preset(TIGHT_KIND, "small", tokens="inputs").tokens == "inputs"


def test_configs_round_trip_through_dicts():
    config = preset(SOLUTION_KIND, "small", n_nodes=7)
    assert config_from_dict(SOLUTION_KIND, config.to_dict()) == config


@pytest.mark.parametrize(
    ("changes", "word"),
    [
        ({"d_model": 15, "n_head": 2}, "divisible"),
        ({"tokens": "nodes"}, "tokens"),
        ({"dropout": 1.0}, "dropout"),
        ({"n_layer": 0}, "n_layer"),
        ({"iter_max": 1}, "iter_max"),
    ],
)
def test_bad_sizes_are_refused_by_name(changes, word):
    with pytest.raises(ValueError, match=word):
        TightConfig(**changes)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: TightConfig(dropout=np.float64(1.0)), "dropout must be in [0, 1), got 1.0"),
        (lambda: SolutionConfig(dropout=np.float32(0.5)), "got float32 0.5"),
        (
            lambda: TscvxPredictor(
                tiny(TIGHT_KIND), tiny(SOLUTION_KIND), normalization(), threshold=np.float64(1.0)
            ),
            "threshold must be in (0, 1), got 1.0",
        ),
    ],
)
def test_numpy_values_are_printed_as_plain_numbers(make, message):
    with pytest.raises(ValueError) as err:
        make()
    assert message in str(err.value) and "np." not in str(err.value)


def test_unknown_kinds_and_fields_are_refused():
    with pytest.raises(ValueError, match="kind"):
        preset("art", "small")
    with pytest.raises(ValueError, match="unknown"):
        config_from_dict(TIGHT_KIND, {"width": 3})
    with pytest.raises(TypeError, match="TightConfig"):
        TightClassifier(SolutionConfig())


def test_networks_refuse_theta_of_the_wrong_width():
    with pytest.raises(ValueError, match="theta"):
        tiny(SOLUTION_KIND)(torch.randn(2, 15))
    with pytest.raises(ValueError, match="k must be"):
        tiny(TIGHT_KIND)(torch.randn(2, 16), torch.tensor([1, 2, 3]))


def test_solution_standardization_round_trips():
    norm = normalization()
    rng = np.random.default_rng(1)
    x, u, tf = rng.normal(size=(2, N, 14)), rng.normal(size=(2, N, 3)), rng.normal(size=2)
    z = norm.encode_solution(x, u, tf)
    assert z.shape == (2, 17 * N + 1)
    assert np.allclose(z[:, -1], (tf - 3.0) / 0.5)
    back = norm.decode_solution(z)
    for got, want in zip(back, (x, u, tf), strict=True):
        np.testing.assert_allclose(got, want)


def _physical_theta(n, seed):
    """theta rows with unit quaternions (the canonical frame needs real attitudes)."""
    rng = np.random.default_rng(seed)
    theta = rng.normal(size=(n, 16))
    theta[:, 8:12] /= np.linalg.norm(theta[:, 8:12], axis=1, keepdims=True)
    return theta


def test_canonical_normalization_needs_theta_and_round_trips_with_it():
    norm = TscvxNormalization(**(normalization().to_dict() | {"canonical": True}))
    rng = np.random.default_rng(1)
    theta = _physical_theta(2, 4)
    x, u, tf = rng.normal(size=(2, N, 14)), rng.normal(size=(2, N, 3)), rng.normal(size=2)
    with pytest.raises(ValueError, match="needs theta"):
        norm.encode_solution(x, u, tf)
    back = norm.decode_solution(norm.encode_solution(x, u, tf, theta), theta)
    for got, want in zip(back, (x, u, tf), strict=True):
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_normalization_dicts_without_the_canonical_key_load_as_raw_frame():
    fields = normalization().to_dict()
    fields.pop("canonical")
    assert TscvxNormalization.from_dict(fields).canonical is False


def test_a_canonical_predictor_is_exactly_equivariant_to_yaw_and_body_roll():
    from scpformer.dynamics import quaternion as quat
    from scpformer.problems.pdg6dof import symmetry as sym

    norm = TscvxNormalization(**(normalization().to_dict() | {"canonical": True}))
    pred = TscvxPredictor(tiny(TIGHT_KIND), tiny(SOLUTION_KIND), norm)
    theta = _physical_theta(3, 5)
    yaw = sym.yaw_quaternion(np.array([30.0, -100.0, 170.0]))
    roll = quat.from_axis_angle([1.0, 0.0, 0.0], np.array([0.4, -2.0, 3.0]))
    moved = sym.roll_theta(sym.yaw_theta(theta, yaw), roll)
    x, u, tf = pred.predict_solution(theta)
    x_m, u_m, tf_m = pred.predict_solution(moved)
    np.testing.assert_allclose(x_m, sym.roll_states(sym.yaw_states(x, yaw[:, None]), roll[:, None]),
                               atol=1e-5)  # fmt: skip
    np.testing.assert_allclose(u_m, sym.roll_body_vectors(u, roll[:, None]), atol=1e-5)
    np.testing.assert_allclose(tf_m, tf, atol=1e-6)
    np.testing.assert_array_equal(pred.predict_tight(moved, 3), pred.predict_tight(theta, 3))


def test_normalization_refuses_zero_std_and_wrong_shapes():
    fields = normalization().to_dict()
    with pytest.raises(ValueError, match="positive"):
        TscvxNormalization(**(fields | {"tf_std": 0.0}))
    with pytest.raises(ValueError, match="theta_mean"):
        TscvxNormalization(**(fields | {"theta_mean": np.zeros(15)}))


def test_predictor_on_raw_theta_equals_the_manual_standardization(predictor):
    rng = np.random.default_rng(2)
    theta = rng.normal(size=(3, 16)) * 4.0
    k = np.array([1, 2, 7])
    norm = predictor.normalization
    z = torch.tensor((theta - norm.theta_mean) / norm.theta_std, dtype=torch.float32)
    with torch.no_grad():
        logits = predictor.tight(z, torch.tensor(k)).numpy()
        out = predictor.solution(z).numpy().astype(np.float64)
    proba = predictor.predict_tight_proba(theta, k)
    np.testing.assert_allclose(proba, 1.0 / (1.0 + np.exp(-logits)), rtol=1e-5)
    np.testing.assert_array_equal(predictor.predict_tight(theta, k), proba > 0.5)
    x, u, tf = predictor.predict_solution(theta)
    np.testing.assert_allclose(x[1], out[1, : 14 * N].reshape(N, 14) * norm.x_std + norm.x_mean,
                               rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(tf, out[:, -1] * 0.5 + 3.0, rtol=1e-6)
    assert u.shape == (3, N, 3)


def test_predictor_single_theta_matches_its_batched_row(predictor):
    theta = np.random.default_rng(3).normal(size=(2, 16))
    flags = predictor.predict_tight(theta[1], 4)
    assert flags.shape == (7 * N,) and flags.dtype == bool
    np.testing.assert_allclose(
        predictor.predict_tight_proba(theta[1], 4), predictor.predict_tight_proba(theta, 4)[1],
        rtol=1e-5,
    )  # fmt: skip
    x, u, tf = predictor.predict_solution(theta[1])
    assert x.shape == (N, 14) and u.shape == (N, 3) and isinstance(tf, float)
    assert predictor.n_nodes == N


@pytest.mark.parametrize("tokens", TOKENIZATIONS)
def test_traced_batch_one_calls_equal_the_eager_networks_for_every_theta_and_k(tokens):
    traced = TscvxPredictor(tiny(TIGHT_KIND, tokens), tiny(SOLUTION_KIND, tokens), normalization())
    eager = TscvxPredictor(tiny(TIGHT_KIND, tokens), tiny(SOLUTION_KIND, tokens), normalization(),
                           trace=False)  # fmt: skip
    traced.warm_up()
    eager.warm_up()
    for i, theta in enumerate(np.random.default_rng(4).normal(size=(3, 16))):
        for k in (1, 2 + i, 9):  # k is an input of the trace, not a constant
            np.testing.assert_allclose(traced.predict_tight_proba(theta, k),
                                       eager.predict_tight_proba(theta, k), rtol=1e-6)  # fmt: skip
        pairs = zip(traced.predict_solution(theta), eager.predict_solution(theta), strict=True)
        for a, b in pairs:
            np.testing.assert_allclose(a, b, rtol=1e-6)
    assert all(isinstance(m, torch.jit.ScriptModule) for m in traced._traced.values())
    assert set(traced._traced) == {"tight", "solution"} and not eager._traced


def test_only_warm_up_traces_and_it_leaves_no_cached_theta(predictor):
    predictor.predict_solution(np.zeros(16))
    predictor.predict_tight(np.zeros(16), 2)
    assert not predictor._traced  # a one-shot solve does not pay for tracing
    predictor.warm_up()
    assert set(predictor._traced) == {"tight", "solution"} and predictor._encoded is None


def test_threshold_moves_the_predicted_set(predictor):
    theta = np.zeros(16)
    assert predictor.predict_tight(theta, 1, threshold=0.01).all()
    assert not predictor.predict_tight(theta, 1, threshold=0.99).any()


@pytest.mark.parametrize(
    ("theta", "k", "error", "word"),
    [
        (np.zeros(15), 1, ValueError, "theta must be"),
        (np.zeros((2, 3, 16)), 1, ValueError, "theta must be"),
        (np.full(16, np.nan), 1, ValueError, "finite"),
        (np.zeros(16), 0, ValueError, "k must be >= 1"),
        (np.zeros(16), 1.5, TypeError, "k must be an int"),
        (np.zeros((2, 16)), np.array([1, 2, 3]), ValueError, r"k must be an int or \(2,\)"),
    ],
)
def test_predictor_refuses_bad_input_by_name(predictor, theta, k, error, word):
    with pytest.raises(error, match=word):
        predictor.predict_tight(theta, k)


def test_predictor_refuses_networks_of_different_sizes():
    with pytest.raises(ValueError, match="disagree on N"):
        TscvxPredictor(tiny(TIGHT_KIND), build_model(SOLUTION_KIND, SolutionConfig(
            d_model=8, n_head=1, n_layer=1, d_ff=8, n_nodes=6)), normalization())  # fmt: skip


def test_predictor_serves_large_batches_and_a_changed_theta_after_a_cached_one(predictor):
    theta = np.random.default_rng(6).normal(size=(300, 16))  # batch size above 255
    first = predictor.predict_tight_proba(theta, 2)
    assert first.shape == (300, 7 * N)
    np.testing.assert_allclose(predictor.predict_tight_proba(theta[:1], 2), first[:1], rtol=1e-5)
    np.testing.assert_allclose(predictor.predict_tight_proba(theta, 2), first)

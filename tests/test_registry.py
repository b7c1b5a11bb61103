"""The policy registry (agents.registry): every list of policies is a view of it, a new expert needs one
entry, and a malformed or duplicate entry is refused with the field, the value and what is allowed."""

import pytest

from agents import BENCHMARK_POLICIES, PAPER_POLICIES, POLICIES, PolicyEntry, make_policy, register, unregister
from agents.policies import BUILT_IN_POLICIES, RGMPCPolicy, is_policy_name, policy_names
from agents.registry import Names
from agents.scripted import HeuristicPolicy
from evaluation import protocols
from lawn_cli import build_parser, main
from lawn_cli.common import policy_help, policy_name
from paper.experiments import EXPERIMENTS
from paper.experiments import base as experiments

NEW = "test-expert"


class NewExpert(RGMPCPolicy):
    """``rg-mpc`` under another name: what a new expert's class is to the registry."""

    name = NEW


@pytest.fixture
def new_expert():
    """A new expert registered for one test (in the suite and the experiments), unregistered after it."""
    entry = register(PolicyEntry(NEW, NewExpert, "expert", "rg-mpc under a test's name", suite=True,
                                 experiments=True))
    yield entry
    unregister(NEW)


def test_the_lists_derive_from_the_registry_in_their_order():
    assert policy_names() == ["dv-mpc", "dv-mpc-ce", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic",
                              "global-mpc"]
    assert [e.name for e in BUILT_IN_POLICIES] == policy_names()
    assert BENCHMARK_POLICIES == ("dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr")
    assert PAPER_POLICIES == ("ao-mpc", "epa", "sf", "pid", "lqr")
    assert protocols.SUITE_POLICIES == ("dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic",
                                        "anchor:stake", "anchor:distance")
    assert experiments.EXPERTS == ("rg-mpc", "ao-mpc")
    assert POLICIES["heuristic"].env_ids == HeuristicPolicy.env_ids == ("lawn/Joint-v1",)  # the class's own
    assert {POLICIES[n].kind for n in BENCHMARK_POLICIES} == {"expert", "baseline"}
    assert POLICIES["global-mpc"].kind == "reference"


def test_a_new_expert_needs_one_entry(new_expert, tmp_path, capsys):
    # lawn evaluate's choices: the name validates, the help lists it, the command plays it
    assert policy_name(NEW) == NEW and is_policy_name(NEW) and NEW in policy_help()
    assert build_parser().parse_args(["evaluate", "--policy", NEW, "--out", "x.csv"]).policy == NEW
    assert main(["evaluate", "--policy", NEW, "--episodes", "1", "--set", "num_slots=3", "--no-score", "--workers",
                 "1", "--quiet", "--out", str(tmp_path / "rows.csv")]) == 0
    assert f"| {NEW} | 1 |" in capsys.readouterr().out
    # the suite's policies, before the anchors, and the experiments' experts (and their sweeps)
    assert protocols.SUITE_POLICIES[-3:] == (NEW, "anchor:stake", "anchor:distance")
    assert NEW in protocols.suite_policies()
    assert experiments.EXPERTS == ("rg-mpc", "ao-mpc", NEW)
    assert EXPERIMENTS["rate"].sweeps(True)["rate"].policies == ("rg-mpc", "ao-mpc", NEW)
    assert NEW not in BENCHMARK_POLICIES  # table=False
    # and it is built by name
    policy = make_policy(NEW, {"num_slots": 3})
    assert isinstance(policy, NewExpert) and policy.env_id == "lawn/Joint-v1"


def test_unregistering_takes_the_entry_off_every_list(new_expert):
    unregister(NEW)
    try:
        assert not is_policy_name(NEW) and NEW not in protocols.SUITE_POLICIES and NEW not in experiments.EXPERTS
        with pytest.raises(ValueError, match="unknown policy 'test-expert'"):
            make_policy(NEW)
    finally:
        register(new_expert)  # the fixture unregisters it


def test_a_duplicate_name_is_refused(new_expert):
    with pytest.raises(ValueError, match=r"name='rg-mpc': a policy of that name is registered"):
        register(PolicyEntry("rg-mpc", NewExpert, "expert", "another rg-mpc"))
    with pytest.raises(ValueError, match=r"name='test-expert'"):
        register(new_expert)
    assert POLICIES["rg-mpc"].factory is RGMPCPolicy


@pytest.mark.parametrize("fields, needle", [
    ({"name": "zoo:mine"}, "name='zoo:mine'"),
    ({"name": ""}, "name=''"),
    ({"factory": 3}, "factory=3 of 'x': must be callable"),
    ({"kind": "oracle"}, "kind='oracle' of 'x': must be one of expert, baseline, reference, learned"),
    ({"description": "two\nlines"}, "must be one non-empty line"),
    ({"kind": "reference", "table": True}, "table=True of 'x', kind='reference': the table list takes kinds expert"),
    ({"kind": "baseline", "experiments": True}, "experiments=True of 'x', kind='baseline'"),
    ({"paper": True}, "paper=True of 'x': the paper's comparison is on the table"),
    ({"suite": 1}, "suite=1 of 'x': must be True or False"),
    ({"env_ids": ("lawn/Nope-v1",)}, "'lawn/Nope-v1' not an env id; valid: lawn/Joint-v1, lawn/Comm-v1"),
    ({"factory": HeuristicPolicy, "env_ids": ("lawn/Comm-v1",)}, "its factory drives lawn/Joint-v1 only"),
    ({"factory": lambda *a, **k: None}, "env_ids=() of 'x': its factory declares none"),
])
def test_a_malformed_entry_is_refused_naming_the_field(fields, needle):
    with pytest.raises(ValueError) as info:
        PolicyEntry(**{"name": "x", "factory": RGMPCPolicy, "kind": "expert", "description": "d", **fields})
    assert needle in str(info.value)


def test_register_and_names_refuse_what_they_do_not_take():
    with pytest.raises(TypeError, match="register takes a PolicyEntry"):
        register(RGMPCPolicy)
    with pytest.raises(ValueError, match="name='nope': no policy of that name is registered"):
        unregister("nope")
    with pytest.raises(ValueError, match="flag='fast': must be one of table, paper, suite, experiments"):
        Names("fast")


def test_a_function_factory_acts_on_the_envs_its_entry_names():
    def factory(config=None, env_id="lawn/Joint-v1", seed=None, **settings):
        return RGMPCPolicy(config, env_id=env_id, seed=seed, **settings)

    register(PolicyEntry("test-joint-only", factory, "expert", "rg-mpc on Joint only", env_ids=("lawn/Joint-v1",)))
    try:
        with pytest.raises(ValueError, match=r"policy 'test-joint-only' drives lawn/Joint-v1; got env_id='lawn/Comm"):
            make_policy("test-joint-only", {"num_slots": 3}, env_id="lawn/Comm-v1")
        assert make_policy("test-joint-only", {"num_slots": 3}).env_id == "lawn/Joint-v1"
    finally:
        unregister("test-joint-only")

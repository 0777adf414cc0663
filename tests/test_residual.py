"""PPO on the clone: the residual policy (baselines/ppo/residual.py) and the failure-state starts
(baselines/ppo/start_states.py)."""

from pathlib import Path

import gymnasium as gym
import pytest
import torch

from baselines.ppo import evaluation, ppo, update
from baselines.ppo.checkpoints import load_checkpoint, load_policy
from baselines.ppo.checkpoints import make_agent
from baselines.ppo import start_states
from baselines.ppo.start_states import StartFromStates
from ms_construction.envs.state_layout import STATE_SIZE

ROOT = Path(__file__).resolve().parents[1]
CLONE = ROOT / "assets/checkpoints/general_agent_clone_direct.pt"
REFINED = ROOT / "assets/checkpoints/general_agent.pt"


def residual_args(tmp_path, **kw) -> ppo.Args:
    return ppo.Args.of(**{**dict(residual_of=str(CLONE), env_id="Flooring-v1", reward_mode="sparse", curiosity="none",
                              curriculum=("cp4",), num_envs=2, num_eval_envs=1, num_steps=40, num_minibatches=2,
                              update_epochs=2, eval_freq=100, checkpoint_freq=1, total_timesteps=80,
                              sim_backend="physx_cpu", log_dir=str(tmp_path), exp_name="residual"), **kw})


def test_the_residual_starts_as_the_clone_and_trains_only_its_own_weights():
    base = load_checkpoint(CLONE)
    torch.manual_seed(0)
    agent = make_agent(dict(base["args"], residual_of=str(CLONE), residual_scale=0.1, curiosity="none"), STATE_SIZE, 6,
                       base_args=base["args"])
    agent.base.load_state_dict(base["agent"])
    clone, _ = load_policy(CLONE, "Flooring-v1")
    obs = torch.randn(64, STATE_SIZE)
    with torch.no_grad():
        assert torch.equal(agent.get_action(obs, deterministic=True), clone.get_action(obs, deterministic=True))
        action, logprob, _, value = agent.get_action_and_value(obs)
    assert action.shape == (64, 6) and logprob.shape == (64,) and value.shape == (64, 1)
    assert not any(p.requires_grad for p in agent.base.parameters())
    assert all(p.requires_grad for n, p in agent.named_parameters() if not n.startswith("base."))


def test_a_residual_that_sees_the_time_starts_as_the_clone_which_does_not():
    """--obs-elapsed-time: the observation's last entry is the time; the base reads the rest, the residual and
    the critic read it too."""
    base = load_checkpoint(CLONE)
    torch.manual_seed(0)
    agent = make_agent(dict(base["args"], residual_of=str(CLONE), residual_scale=0.1, curiosity="none",
                            obs_elapsed_time=True), STATE_SIZE + 1, 6, base_args=base["args"])
    agent.base.load_state_dict(base["agent"])
    clone, _ = load_policy(CLONE, "Flooring-v1")
    obs = torch.randn(64, STATE_SIZE + 1)
    with torch.no_grad():
        assert torch.equal(agent.get_action(obs, deterministic=True), clone.get_action(obs[:, :-1], deterministic=True))
        late = obs.clone()
        late[:, -1] = 0.9
        assert not torch.equal(agent.get_value(obs), agent.get_value(late)), "the critic sees the time"
    assert agent.residual_mean[0].in_features == agent.critic[0].in_features == STATE_SIZE + 2 * 3 + 6 + 1


def test_bootstrapping_at_terminated_ends_keeps_success_and_drops_the_time_limit():
    terminated, truncated = torch.tensor([[1.0, 0.0, 0.0]]), torch.tensor([[0.0, 1.0, 0.0]])
    masks = {mode: update.bootstrap_mask(terminated, truncated, mode).tolist()
             for mode in ("always", "truncated", "terminated", "never")}
    assert masks == {"always": [[1, 1, 0]], "truncated": [[0, 1, 0]], "terminated": [[1, 0, 0]], "never": [[0, 0, 0]]}


def test_the_l2_anchor_pulls_the_correction_back_to_the_clone():
    """With advantages of zero the policy loss has no gradient, so an update with --residual-l2-coef moves
    only the correction, and towards zero (the clone's own action)."""
    base = load_checkpoint(CLONE)
    torch.manual_seed(0)
    agent = make_agent(dict(base["args"], residual_of=str(CLONE), residual_scale=0.1, curiosity="none"), STATE_SIZE, 6,
                       base_args=base["args"])
    agent.base.load_state_dict(base["agent"])
    torch.nn.init.normal_(agent.residual_mean[-1].weight, std=0.5)  # a correction that has moved away from zero
    obs = torch.randn(256, STATE_SIZE)
    with torch.no_grad():
        actions, logprobs, _, values = agent.get_action_and_value(obs)
    batch = dict(obs=obs, next_obs=obs, actions=actions, logprobs=logprobs, advantages=torch.zeros(256),
                 returns=values, values=values)
    before = agent.correction(obs).pow(2).sum(-1).mean().item()
    args = ppo.Args.of(residual_of=str(CLONE), residual_l2_coef=1.0, num_minibatches=1, update_epochs=5, target_kl=None,
                    norm_adv="none")
    losses = update.ppo_update(agent, update.adam([p for p in agent.parameters() if p.requires_grad], lr=1e-3), batch, args)
    after = agent.correction(obs).pow(2).sum(-1).mean().item()
    assert 0 < losses["residual_l2"] <= before and after < 0.9 * before


def test_a_second_round_residual_starts_as_the_refined_agent_and_keeps_it_frozen(tmp_path):
    """--residual-of a refined agent (itself a residual on the clone): the corrections add up, the new one starts
    at zero, and the checkpoint carries both bases' args so that scripts/evaluate.py loads it."""
    refined = load_checkpoint(REFINED)
    assert refined["base_args"] is not None, "the shipped agent is a residual on the clone"
    torch.manual_seed(0)
    agent = make_agent(dict(refined["args"], residual_of=str(REFINED), obs_elapsed_time=False), STATE_SIZE, 6,
                       base_args={**refined["args"], "base_args": refined["base_args"]})
    agent.base.load_state_dict(refined["agent"])
    shipped, _ = load_policy(REFINED, "Flooring-v1")
    obs = torch.randn(64, STATE_SIZE)
    with torch.no_grad():
        assert torch.equal(agent.get_action(obs, deterministic=True), shipped.get_action(obs, deterministic=True))
    assert not any(p.requires_grad for p in agent.base.parameters())

    ppo.main(residual_args(tmp_path, residual_of=str(REFINED)))
    ckpt_path = tmp_path / "residual" / "checkpoint.pt"
    ckpt = load_checkpoint(ckpt_path)
    for k, v in refined["agent"].items():
        assert torch.equal(ckpt["agent"][f"base.{k}"], v), f"the refined base stays as it was: {k}"
    assert ckpt["base_args"]["base_args"].get("residual_of") is None, "the clone is the innermost base"
    assert ckpt["agent"]["residual_mean.6.weight"].abs().sum() > 0, "the new correction has learnt"
    result = evaluation.main(evaluation.Args(checkpoint=ckpt_path, env_id="Flooring-v1", episodes=2, workers=1))
    assert result["Flooring-v1"]["episodes"] == 2


def test_a_residual_that_sees_the_time_is_refused_as_a_base(tmp_path):
    timed = load_checkpoint(REFINED)
    timed["args"] = dict(timed["args"], obs_elapsed_time=True)
    timed["obs_dim"] = STATE_SIZE + 1
    torch.save(timed, tmp_path / "timed.pt")
    with pytest.raises(SystemExit, match="elapsed time cannot be another residual's base"):
        ppo.main(residual_args(tmp_path, residual_of=str(tmp_path / "timed.pt")))


@pytest.mark.parametrize("timed", [False, True], ids=["clone's observation", "elapsed time observed"])
def test_a_short_residual_run_changes_the_policy_resumes_and_evaluates(tmp_path, timed):
    kw = dict(obs_elapsed_time=True, bootstrap_at_done="terminated") if timed else {}
    ppo.main(residual_args(tmp_path, **kw))
    ckpt_path = tmp_path / "residual" / "checkpoint.pt"
    ckpt = load_checkpoint(ckpt_path)
    assert ckpt["base_args"] is not None and ckpt["progress"]["global_step"] == 80
    base = load_checkpoint(CLONE)
    for k, v in base["agent"].items():
        assert torch.equal(ckpt["agent"][f"base.{k}"], v), f"the base stays as it was: {k}"
    assert ckpt["agent"]["residual_mean.6.weight"].abs().sum() > 0, "the correction has learnt"
    assert ckpt["obs_dim"] == STATE_SIZE + timed
    progress = ppo.main(residual_args(tmp_path, total_timesteps=160, **kw).replace(resume=str(ckpt_path), extend=True))
    assert progress.global_step == 160
    _, env_kwargs = load_policy(ckpt_path, "Flooring-v1")  # what scripts/evaluate.py loads
    assert env_kwargs.get("obs_elapsed_time", False) == timed
    result = evaluation.main(evaluation.Args(checkpoint=ckpt_path, env_id="Flooring-v1", episodes=2, workers=1))
    assert result["Flooring-v1"]["episodes"] == 2


def test_a_share_of_resets_start_from_the_bank(tmp_path):
    env = gym.make("Flooring-v1", obs_mode="state", num_envs=1, sim_backend="physx_cpu")
    env.reset(seed=3)
    for _ in range(5):
        env.step(env.action_space.sample())
    state = env.unwrapped.get_state_dict()
    marker = env.unwrapped.obj.pose.p.clone()
    bank = tmp_path / "bank.pt"
    torch.save(dict(states=[state]), bank)
    wrapped = StartFromStates(env, str(bank), share=1.0)
    obs, _ = wrapped.reset(seed=0)
    assert torch.allclose(env.unwrapped.obj.pose.p, marker, atol=1e-5), "reset into the bank's state"
    assert torch.allclose(obs, env.unwrapped.get_obs())
    never = StartFromStates(env, str(bank), share=0.0)
    never.reset(seed=3)
    assert not torch.allclose(env.unwrapped.obj.pose.p, marker, atol=1e-3), "an ordinary reset"
    env.close()


def test_a_bank_episode_keeps_the_clock_of_its_state_when_asked(tmp_path):
    """Most failed windows run out of time: restarted with the whole step limit they would not (start_states.py)."""
    env = gym.make("Flooring-v1", obs_mode="state", num_envs=1, sim_backend="physx_cpu", obs_elapsed_time=True)
    env.reset(seed=3)
    state = env.unwrapped.get_state_dict()
    bank = tmp_path / "bank.pt"
    torch.save(dict(states=[state], elapsed=[248]), bank)
    obs, _ = StartFromStates(env, str(bank), share=1.0, keep_clock=True).reset(seed=0)
    assert int(env.unwrapped.elapsed_steps[0]) == 248 and obs[0, -1].item() == pytest.approx(248 / 250)
    truncated = [bool(env.step(torch.zeros(1, 6))[3][0]) for _ in range(2)]
    assert truncated == [False, True], "the step limit counts on from the state's own step"
    StartFromStates(env, str(bank), share=1.0).reset(seed=0)
    assert int(env.unwrapped.elapsed_steps[0]) == 0, "by default a bank episode has the whole limit"
    torch.save(dict(states=[state]), bank)
    with pytest.raises(ValueError, match="no elapsed steps"):
        StartFromStates(env, str(bank), share=1.0, keep_clock=True)
    env.close()


class _TurnBase:
    """A policy that only turns the arm's base joint, so never places, and whose every step leaves another arm state."""

    def get_action(self, obs, deterministic=True):
        return torch.tensor([[0.5, 0, 0, 0, 0, 0]]).expand(obs.shape[0], 6)


def test_a_failed_episode_s_states_are_banked_with_the_steps_they_were_taken_at(monkeypatch):
    env = gym.make("Flooring-v1", obs_mode="state", reward_mode="sparse", num_envs=1, sim_backend="physx_cpu")
    # the distances after actions 0..4 were closest after action 3, in the state at step 4
    assert start_states.steps_before_closest([5, 4, 3, 1, 2], (-2, 0)) == [2, 4]
    assert start_states.steps_before_closest([5, 4, 3, 1, 2], (-30, -10)) == [0]
    monkeypatch.setattr(start_states, "_worker", dict(agent=_TurnBase(), env=env))
    # the element never moves here, so its closest approach is noise: ask for two steps apart instead
    monkeypatch.setattr(start_states, "steps_before_closest", lambda dists, offsets: [37, 120])
    result = start_states._failure_states(("unused.pt", "Flooring-v1", 11, (-30, -10), None))
    assert not result["placed"] and result["elapsed"] == [37, 120] and len(result["states"]) == 2
    obs, _ = env.reset(seed=11)  # the same episode again: the arm after t actions is the banked state at t
    arms = [env.unwrapped.get_state_dict()["articulations"]]
    for _ in range(max(result["elapsed"])):
        env.step(_TurnBase().get_action(obs))
        arms.append(env.unwrapped.get_state_dict()["articulations"])
    for state, t in zip(result["states"], result["elapsed"]):
        for name, arm in state["articulations"].items():
            assert torch.allclose(arm, arms[t][name], atol=1e-5), f"the state banked as step {t} is the arm after {t} actions"
    with pytest.raises(ValueError, match="offsets"):
        start_states.collect_failure_states(Path("unused.pt"), 1, offsets=(10,))
    env.close()


def residual_snapshot(path: Path, shift: float, base_shift: float = 0.0) -> Path:
    """A residual checkpoint on the clone whose own weights are all `shift` (its base's first weight moved
    by `base_shift`)."""
    base = load_checkpoint(CLONE)
    args = dict(base["args"], residual_of=str(CLONE), residual_scale=0.1, curiosity="none")
    agent = make_agent(args, STATE_SIZE, 6, base_args=base["args"])
    agent.base.load_state_dict(base["agent"])
    state = {k: v if k.startswith("base.") or not v.is_floating_point() else torch.full_like(v, shift)
             for k, v in agent.state_dict().items()}
    state["base.actor_mean.0.weight"] = state["base.actor_mean.0.weight"] + base_shift
    torch.save(dict(args=args, base_args=base["args"], obs_dim=STATE_SIZE, act_dim=6, task_slots=4, agent=state, progress={}),
               path)
    return path


def test_averaged_snapshots_hold_the_mean_of_their_weights_and_the_base_unchanged(tmp_path):
    from baselines.ppo.checkpoints import average_checkpoints

    paths = [residual_snapshot(tmp_path / f"s{i}.pt", shift) for i, shift in enumerate((0.1, 0.2, 0.6))]
    out = tmp_path / "average.pt"
    average_checkpoints(paths, out)
    avg = load_checkpoint(out)
    assert torch.allclose(avg["agent"]["residual_mean.0.weight"], torch.full_like(avg["agent"]["residual_mean.0.weight"], 0.3))
    assert torch.allclose(avg["agent"]["actor_logstd"], torch.full_like(avg["agent"]["actor_logstd"], 0.3))
    base = load_checkpoint(CLONE)
    for k, v in base["agent"].items():
        assert torch.equal(avg["agent"][f"base.{k}"], v), k
    assert avg["averaged_from"] == [str(p) for p in paths]
    load_policy(out, "Flooring-v1")  # what scripts/evaluate.py loads


def test_snapshots_whose_frozen_base_differs_are_not_averaged(tmp_path):
    from baselines.ppo.checkpoints import average_checkpoints

    paths = [residual_snapshot(tmp_path / "a.pt", 0.1), residual_snapshot(tmp_path / "b.pt", 0.2, base_shift=0.5)]
    with pytest.raises(SystemExit, match="base.actor_mean.0.weight differs"):
        average_checkpoints(paths, tmp_path / "average.pt")

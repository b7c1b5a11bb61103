"""Single-file PPO (CleanRL style) for lawn/JointRL-v1 on Gymnasium >= 1.0.

    python examples/ppo_lawn.py --total-timesteps 200000 --num-envs 4 --seed 1

It trains on the RL interface (anchored actions, a bounded reward, termination: docs/rl.md), logs
every finished episode's return and length, and ends with what counts: the realized control cost of
full episodes of the unmodified scenario (lawn/Joint-v1's physics, the same seeds) under the
trained policy and under the zero action of the same interface (``--eval-episodes``).

Gymnasium 1.x: SyncVectorEnv's default ``autoreset_mode`` is NEXT_STEP: the step that ends an episode
returns its final observation, and the next step resets that sub-env, ignores its action and returns
reward 0 (a row that is no transition: masked out of the loss here). SAME_STEP resets inside the ending
step (as 0.29 did), with the final observation in ``infos["final_obs"]``. RecordEpisodeStatistics' stats
are ``infos["episode"]["r"/"l"][i]`` where ``infos["_episode"][i]`` (NEXT_STEP), or the same under
``infos["final_info"]`` (SAME_STEP).
"""
import argparse
import ast
import importlib.util
import inspect
import time
from dataclasses import dataclass, fields
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import torch.optim as optim
from gymnasium.vector import AutoresetMode
from torch.distributions.normal import Normal

import lawn_env  # noqa: F401  (registers the lawn/* ids)

EVAL_SEED_BASE = 500_000  # lawn's validation seeds (training/validation.py): never the training episodes


@dataclass
class Args:
    env_id: str = "lawn/JointRL-v1"
    """the Gymnasium id to train on"""
    seed: int = 1
    """seed of the experiment (sub-env i is reset with seed + i)"""
    total_timesteps: int = 200_000
    """total environment steps over all sub-envs"""
    num_envs: int = 4
    """the number of sub-envs in the SyncVectorEnv"""
    num_steps: int = 256
    """the number of steps per sub-env in each rollout"""
    autoreset_mode: str = "NextStep"
    """the vector env's autoreset mode: NextStep (Gymnasium's default) or SameStep"""
    bootstrap_truncated: bool = True
    """bootstrap the value at truncation (the 120-slot limit); off: treat it as termination, as CleanRL does"""
    learning_rate: float = 3e-4
    """the learning rate of the optimizer (annealed linearly to 0)"""
    gamma: float = 0.99
    """the discount factor gamma"""
    gae_lambda: float = 0.95
    """the lambda for the general advantage estimation"""
    num_minibatches: int = 8
    """the number of mini-batches per epoch"""
    update_epochs: int = 10
    """the K epochs to update the policy"""
    clip_coef: float = 0.2
    """the surrogate clipping coefficient"""
    ent_coef: float = 0.0
    """coefficient of the entropy"""
    vf_coef: float = 0.5
    """coefficient of the value function"""
    max_grad_norm: float = 0.5
    """the maximum norm for the gradient clipping"""
    target_kl: float = 0.0
    """stop an update's epochs once the approximate KL exceeds this (0: never)"""
    norm_obs: bool = True
    """normalize observations with running statistics (then clip to [-10, 10])"""
    norm_reward: bool = True
    """scale rewards by a running estimate of the discounted return's std (then clip to [-10, 10])"""
    init_logstd: float = -1.0
    """initial log std of the Gaussian policy (the zero action is the anchor: explore near it)"""
    summary_episodes: int = 10
    """the summary line averages over this many first and last logged episodes"""
    eval_episodes: int = 5
    """full episodes (seeds 500000..) of the trained policy and of the zero action at the end (0: none)"""
    torch_threads: int = 1
    """torch CPU threads"""
    markdown: str = ""
    """also write the run's summary and evaluation as a Markdown table to this file (docs/clients.md's)"""


def parse_args() -> Args:
    if importlib.util.find_spec("tyro"):
        return importlib.import_module("tyro").cli(Args)
    # the attribute docstrings (what tyro shows) become the argparse help
    body = ast.parse(inspect.getsource(Args)).body[0].body
    docs = {a.target.id: b.value.value for a, b in zip(body, body[1:])
            if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr)}
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for f in fields(Args):
        flag = "--" + f.name.replace("_", "-")
        if f.type in (bool, "bool"):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default, help=docs.get(f.name))
        else:
            parser.add_argument(flag, type=type(f.default), default=f.default, help=docs.get(f.name))
    return Args(**vars(parser.parse_args()))


def make_env(args: Args):
    def thunk():
        env = gym.make(args.env_id)
        env = gym.wrappers.RecordEpisodeStatistics(env)  # innermost: raw returns and lengths
        env = gym.wrappers.ClipAction(env)
        if args.norm_obs:
            env = gym.wrappers.NormalizeObservation(env)
            clipped = gym.spaces.Box(-10.0, 10.0, env.observation_space.shape, np.float32)
            env = gym.wrappers.TransformObservation(env, lambda o: np.clip(o, -10, 10), clipped)
        if args.norm_reward:
            env = gym.wrappers.NormalizeReward(env, gamma=args.gamma)
            env = gym.wrappers.TransformReward(env, lambda r: np.clip(r, -10, 10))
        return env
    return thunk


def finished_episodes(infos: dict, mode: AutoresetMode):
    """(sub-env index, return, length) of every episode that ended in this step."""
    stats = infos if mode == AutoresetMode.NEXT_STEP else infos.get("final_info", {})
    ep, mask = stats.get("episode"), stats.get("_episode", np.zeros(0, bool))
    return [(i, float(ep["r"][i]), int(ep["l"][i])) for i in np.flatnonzero(mask)]


def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    def __init__(self, obs_dim: int, act_dim: int, init_logstd: float):
        super().__init__()
        def mlp(out, std):
            return nn.Sequential(layer_init(nn.Linear(obs_dim, 64)), nn.Tanh(), layer_init(nn.Linear(64, 64)),
                                 nn.Tanh(), layer_init(nn.Linear(64, out), std=std))
        self.critic = mlp(1, 1.0)
        self.actor_mean = mlp(act_dim, 0.01)  # starts near the zero action (the anchor)
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), init_logstd))

    def get_value(self, x):
        return self.critic(x).squeeze(-1)

    def get_action_and_value(self, x, action=None):
        mean = self.actor_mean(x)
        dist = Normal(mean, self.actor_logstd.expand_as(mean).exp())
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(1), dist.entropy().sum(1), self.get_value(x)


def control_cost(env: gym.Env, act, seed: int) -> tuple[float, bool]:
    """The realized control cost of one episode (MODEL.md §6) and whether it ran to its last slot."""
    obs, info = env.reset(seed=seed)
    terminated = truncated = False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(act(obs))
    return float(info["episode_metrics"]["control_cost"]), bool(truncated and not terminated)


def _obs_normalizer(env: gym.Env) -> gym.wrappers.NormalizeObservation:
    """The NormalizeObservation wrapper inside ``env``'s stack."""
    while not isinstance(env, gym.wrappers.NormalizeObservation):
        env = env.env
    return env


def evaluate(agent: Agent, args: Args, train_env: gym.Env) -> tuple[float, float, float]:
    """The trained policy's mean action and the zero action on the same seeds, on the training
    interface with the training run's observation statistics frozen: full episodes, their cost."""
    env = make_env(args)()
    if args.norm_obs:  # the statistics the policy was trained with, no longer updated
        source, target = _obs_normalizer(train_env), _obs_normalizer(env)
        target.obs_rms.mean, target.obs_rms.var = source.obs_rms.mean.copy(), source.obs_rms.var.copy()
        target.obs_rms.count = source.obs_rms.count
        target.update_running_mean = False  # this wrapper's own flag (NormalizeReward has one too)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)

    def policy(obs):
        with torch.no_grad():
            return agent.actor_mean(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()

    seeds = range(EVAL_SEED_BASE, EVAL_SEED_BASE + args.eval_episodes)
    learned = [control_cost(env, policy, s) for s in seeds]
    anchor = [control_cost(env, lambda _: zero, s) for s in seeds]
    ratios = np.log([a / b for (a, _), (b, _) in zip(learned, anchor)])
    print(f"evaluation: {args.eval_episodes} episodes, control cost {np.mean([c for c, _ in learned]):.1f} "
          f"(full episodes {sum(f for _, f in learned)}), zero action {np.mean([c for c, _ in anchor]):.1f}; "
          f"learned vs zero action {np.expm1(ratios.mean()) * 100:+.1f} % (geometric mean of the per-seed ratios)")
    env.close()
    return float(np.mean([c for c, _ in learned])), float(np.mean([c for c, _ in anchor])), float(np.expm1(ratios.mean()))


def write_markdown(path: str, args: Args, episodes: list, evaluation: tuple[float, float, float] | None) -> None:
    """The run's summary (episodes, full-length ones, the first and last logged returns) and its
    evaluation (control cost of the trained policy and of the zero action) as one Markdown table."""
    k = min(args.summary_episodes, len(episodes))
    returns = np.array([e[1] for e in episodes]) if episodes else np.zeros(0)
    cells = [f"{args.total_timesteps:,}", f"{len(episodes):,}", f"{sum(e[2] == 120 for e in episodes):,}",
             f"{returns[:k].mean():.1f}" if k else "n/a", f"{returns[-k:].mean():.1f}" if k else "n/a"]
    cells += [f"{evaluation[0]:.1f}", f"{evaluation[1]:.1f}", f"{evaluation[2] * 100:+.1f} %"] if evaluation else \
        ["n/a"] * 3
    header = ["steps", "episodes", "of 120 slots", f"mean return, first {k}", f"mean return, last {k}",
              f"control cost, trained ({args.eval_episodes} validation seeds)", "control cost, zero action",
              "trained vs zero action (geometric)"]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
                                     "| " + " | ".join(cells) + " |"]) + "\n")


if __name__ == "__main__":
    args = parse_args()
    mode = AutoresetMode(args.autoreset_mode)
    batch_size = args.num_envs * args.num_steps
    num_iterations = max(1, args.total_timesteps // batch_size)
    torch.manual_seed(args.seed), np.random.seed(args.seed), torch.set_num_threads(args.torch_threads)

    envs = gym.vector.SyncVectorEnv([make_env(args) for _ in range(args.num_envs)], autoreset_mode=mode)
    assert isinstance(envs.single_action_space, gym.spaces.Box), "only continuous action spaces are supported"
    obs_shape, act_shape = envs.single_observation_space.shape, envs.single_action_space.shape
    agent = Agent(int(np.prod(obs_shape)), int(np.prod(act_shape)), args.init_logstd)
    optimizer = optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    T, N = args.num_steps, args.num_envs
    obs, actions = torch.zeros((T, N) + obs_shape), torch.zeros((T, N) + act_shape)
    logprobs, rewards, values, final_values = (torch.zeros((T, N)) for _ in range(4))
    # final_values (SAME_STEP): V(final obs) of the episodes that ended at this step
    cuts = torch.zeros((T, N))       # 1: no bootstrap from the next state (terminated, or any end if not bootstrapping)
    ends = torch.zeros((T, N))       # 1: the episode ended at this step (GAE does not cross it)
    valid = torch.ones((T, N))       # 0: a NEXT_STEP reset row (action ignored, not a transition)

    episodes = []  # (global_step, return, length)
    global_step, start = 0, time.time()
    next_obs = torch.as_tensor(envs.reset(seed=args.seed)[0], dtype=torch.float32)
    resetting = np.zeros(N, dtype=bool)  # NEXT_STEP: these sub-envs reset on the next step

    for iteration in range(1, num_iterations + 1):
        optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate
        for step in range(T):
            global_step += N
            obs[step] = next_obs
            valid[step] = torch.as_tensor(~resetting, dtype=torch.float32)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs)
            actions[step], logprobs[step], values[step] = action, logprob, value

            next_obs, reward, term, trunc, infos = envs.step(action.numpy())
            done = np.logical_or(term, trunc)
            rewards[step] = torch.as_tensor(reward, dtype=torch.float32)
            ends[step] = torch.as_tensor(done, dtype=torch.float32)
            cuts[step] = torch.as_tensor(term if args.bootstrap_truncated else done, dtype=torch.float32)
            if mode == AutoresetMode.NEXT_STEP:
                resetting = done  # next_obs holds the final observations: values[step + 1] bootstraps them
            elif done.any():      # SAME_STEP: next_obs holds reset observations; the final ones are in infos
                idx = np.flatnonzero(done)
                final = torch.as_tensor(np.stack(infos["final_obs"][idx]), dtype=torch.float32)
                with torch.no_grad():
                    final_values[step, idx] = agent.get_value(final)
            next_obs = torch.as_tensor(next_obs, dtype=torch.float32)

            for i, ret, length in finished_episodes(infos, mode):
                episodes.append((global_step, ret, length))
                print(f"global_step={global_step}, env={i}, episodic_return={ret:.3f}, episodic_length={length}")

        # GAE: delta_t = r_t + gamma V(s'_t) (1 - cut_t) - V(s_t); the recursion stops where an episode ended
        with torch.no_grad():
            next_values = torch.cat([values[1:], agent.get_value(next_obs).unsqueeze(0)])
            if mode == AutoresetMode.SAME_STEP:
                next_values = torch.where(ends.bool(), final_values, next_values)
            advantages, lastgaelam = torch.zeros((T, N)), torch.zeros(N)
            for t in reversed(range(T)):
                delta = rewards[t] + args.gamma * next_values[t] * (1.0 - cuts[t]) - values[t]
                lastgaelam = (delta + args.gamma * args.gae_lambda * (1.0 - ends[t]) * lastgaelam) * valid[t]
                advantages[t] = lastgaelam
            returns = advantages + values

        keep = valid.reshape(-1).bool()
        b_obs, b_actions = obs.reshape((-1,) + obs_shape)[keep], actions.reshape((-1,) + act_shape)[keep]
        b_logprobs, b_adv = logprobs.reshape(-1)[keep], advantages.reshape(-1)[keep]
        b_returns, b_values = returns.reshape(-1)[keep], values.reshape(-1)[keep]
        n = len(b_obs)
        mb_size = max(1, n // args.num_minibatches)
        clipfracs, approx_kl = [], torch.tensor(0.0)
        for epoch in range(args.update_epochs):
            perm = np.random.permutation(n)
            for lo in range(0, n, mb_size):
                mb = perm[lo:lo + mb_size]
                _, newlogprob, entropy, newvalue = agent.get_action_and_value(b_obs[mb], b_actions[mb])
                logratio = newlogprob - b_logprobs[mb]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()
                    clipfracs.append(((ratio - 1.0).abs() > args.clip_coef).float().mean().item())
                adv = b_adv[mb]
                if len(mb) > 1:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
                v_clipped = b_values[mb] + (newvalue - b_values[mb]).clamp(-args.clip_coef, args.clip_coef)
                v_loss = 0.5 * torch.max((newvalue - b_returns[mb]) ** 2, (v_clipped - b_returns[mb]) ** 2).mean()
                loss = pg_loss - args.ent_coef * entropy.mean() + args.vf_coef * v_loss
                optimizer.zero_grad(), loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()
            if args.target_kl > 0 and approx_kl > args.target_kl:
                break

        sps = int(global_step / (time.time() - start))
        print(f"iteration={iteration}/{num_iterations} global_step={global_step} transitions={n} "
              f"v_loss={v_loss.item():.4f} pg_loss={pg_loss.item():.4f} approx_kl={approx_kl.item():.4f} "
              f"clipfrac={np.mean(clipfracs):.3f} SPS={sps}")

    evaluation = evaluate(agent, args, envs.envs[0]) if args.eval_episodes > 0 else None
    envs.close()
    if args.markdown:
        write_markdown(args.markdown, args, episodes, evaluation)
    k = min(args.summary_episodes, len(episodes))
    if k:
        first, last = np.array(episodes[:k])[:, 1:], np.array(episodes[-k:])[:, 1:]
        print(f"summary: episodes={len(episodes)} mean_length={np.mean([e[2] for e in episodes]):.1f} "
              f"first{k}: mean_return={first[:, 0].mean():.3f} mean_length={first[:, 1].mean():.1f} | "
              f"last{k}: mean_return={last[:, 0].mean():.3f} mean_length={last[:, 1].mean():.1f}")
    else:
        print("summary: no episode finished (raise --total-timesteps or --num-steps)")

"""What every learner shares: its config, the policy networks, results and checkpoints.

The policy is a Gaussian (paper Eq. 5): an MLP gives the mean action, a learned
state-independent log standard deviation gives the spread; the critic is an MLP of the
same shape. Both read the observation through one ``RunningNorm``, which keeps the
normalisation statistics inside the networks' ``state_dict``, so a checkpoint alone
reproduces the policy (no environment transform to restore).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NotRequired, Protocol, TypedDict

import pandas as pd
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import MLP, IndependentNormal, ProbabilisticActor, ValueOperator

from evo.checks import at_least, within
from evo.envs.params import ACTUATOR_SLOTS, action_size, observation_origins
from evo.robot.tree import Robot
from evo.run.files import write_bytes

if TYPE_CHECKING:
    from evo.learners import Learner


@dataclass(frozen=True, slots=True)
class LearnerConfig:
    """The settings every learner shares, a base class: the class a ``conf/learner/*.yaml``
    names with ``_target_`` (:class:`evo.learners.ppo.PPO`) is a subclass that says which
    ``train`` function it configures (:meth:`train_function`) and its label (:attr:`name`).

    Attributes:
        update: Whether the policy is trained (False for the random learner).
        total_steps: Training budget in env steps when run alone (``task=train``; the GA
            sets its own).
        num_envs: Arenas stepped together in one process.
        rollout_steps: Control steps per arena per collector batch (a batch is
            ``num_envs x rollout_steps`` env steps).
        epochs: Passes over each batch.
        minibatch_size: Samples per gradient step.
        lr: Adam learning rate, decayed linearly to 0 over the budget if ``anneal_lr``.
        anneal_lr: Decay the learning rate linearly over the budget.
        gamma: Discount factor per control step (0.05 s).
        lmbda: GAE lambda.
        clip_epsilon: PPO ratio clip.
        entropy_coeff: Weight of the entropy bonus.
        critic_coeff: Weight of the value loss.
        max_grad_norm: Gradient norm clip.
        hidden: Hidden layer widths of the policy and value MLPs.
        init_log_std: Initial log standard deviation of the Gaussian policy.
        policy_out_gain: Gain of the orthogonal initialisation of the policy's last
            layer: 0.01 starts every mean action near zero (Andrychowicz et al. 2021),
            1 as large as the layers before it, 0 exactly zero.
        normalize_obs: Normalise observations with running statistics.
        reward_scaling: Divide the rewards the update sees by the running standard
            deviation of the discounted return (Engstrom et al. 2020); the curve and
            the fitness keep the env's rewards.
        eval_episodes: Episodes of the deterministic evaluation after training
            (``task=train``, and ``retrain.evaluate``).
        eval_interval: Env steps between the periodic deterministic evaluations during
            training (the curve's ``eval/`` keys; each after the batch that reaches a
            multiple of it, and one after the last batch); 0: none. They take env steps
            of their own, not the budget's, and no random numbers of the training's.
        eval_interval_episodes: Episodes (one per arena, side by side) of each periodic
            evaluation, under seed + 2: other targets than the evaluation after training.
        keep_best: Hand back (and write) the policy of the best periodic evaluation,
            by success rate and then mean return, instead of the last one (needs
            ``eval_interval``); the fitness stays the training's (Eq. 8).
        bound_mean: Squash the Gaussian's mean into the action box [-1, 1] with tanh,
            so the mean action never lies where the env clips every action.
        final_log_std: Anneal an upper bound of the log standard deviation linearly
            from ``init_log_std`` at the first batch to this at the budget's end;
            None: no bound (the log std is learned freely).
        anneal_from: The fraction of the budget at which that bound starts to fall
            (before it the bound is ``init_log_std``): 0 anneals over the whole
            budget, 0.5 over its second half.
        average_from: Average the actor's weights over the updates from this fraction
            of the budget on (stochastic weight averaging, Izmailov et al. 2018: the
            uniform mean of the weights after each batch's update) and hand back, and
            evaluate from then on, the averaged actor; the training's own batches keep
            acting with the current weights. None: no averaging.
    """

    update: bool = True
    total_steps: int = 150_000
    num_envs: int = 32
    rollout_steps: int = 64
    epochs: int = 4
    minibatch_size: int = 512
    lr: float = 3e-4
    anneal_lr: bool = True
    gamma: float = 0.99
    lmbda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coeff: float = 0.005
    critic_coeff: float = 0.5
    max_grad_norm: float = 0.5
    hidden: tuple[int, ...] = (128, 128)
    init_log_std: float = -0.5
    policy_out_gain: float = 0.01
    normalize_obs: bool = True
    reward_scaling: bool = False
    eval_episodes: int = 20
    eval_interval: int = 0
    eval_interval_episodes: int = 16
    keep_best: bool = False
    bound_mean: bool = False
    final_log_std: float | None = None
    anneal_from: float = 0.0
    average_from: float | None = None

    def __post_init__(self) -> None:
        at_least(self, 1, "total_steps", "num_envs", "rollout_steps", "epochs",
                 "minibatch_size")
        ranges = (("lr", self.lr > 0, "> 0"), ("gamma", 0 < self.gamma <= 1, "in (0, 1]"),
                  ("lmbda", 0 <= self.lmbda <= 1, "in [0, 1]"),
                  ("clip_epsilon", self.clip_epsilon > 0, "> 0"),
                  ("max_grad_norm", self.max_grad_norm > 0, "> 0"),
                  ("entropy_coeff", self.entropy_coeff >= 0, ">= 0"),
                  ("critic_coeff", self.critic_coeff >= 0, ">= 0"),
                  ("policy_out_gain", self.policy_out_gain >= 0, ">= 0"))
        for key, ok, expected in ranges:
            if not ok:
                raise ValueError(f"{key} must be {expected}, got {getattr(self, key)}")
        at_least(self, 0, "eval_episodes", "eval_interval")
        at_least(self, 1, "eval_interval_episodes")
        within(self, -10, 2, "init_log_std", note=" (a standard deviation of e^-10 to e^2)")
        if self.final_log_std is not None:
            within(self, -10, 2, "final_log_std", note=" (a standard deviation of e^-10 to "
                   "e^2), or null for none")
        if not 0 <= self.anneal_from < 1:
            raise ValueError(f"anneal_from must be in [0, 1) (a fraction of the budget), "
                             f"got {self.anneal_from}")
        if self.average_from is not None and not 0 <= self.average_from < 1:
            raise ValueError(f"average_from must be in [0, 1) (a fraction of the budget), "
                             f"or null for none, got {self.average_from}")
        if self.keep_best and not self.eval_interval:
            raise ValueError("keep_best needs periodic evaluations to choose from: set "
                             "eval_interval (env steps) > 0")
        if self.minibatch_size > self.frames_per_batch:
            raise ValueError(
                f"minibatch_size ({self.minibatch_size}) must be <= the batch, num_envs x "
                f"rollout_steps = {self.num_envs} x {self.rollout_steps} = "
                f"{self.frames_per_batch} env steps")
        if not self.hidden or min(self.hidden) < 1:
            raise ValueError(f"hidden must list positive layer widths, got {self.hidden}")

    @property
    def name(self) -> str:
        """The learner's label (progress, a training's ``summary.json``)."""
        raise NotImplementedError(f"{type(self).__name__} has no learner name")

    def train_function(self) -> Learner:
        """The ``train`` function these settings are for."""
        raise NotImplementedError(f"{type(self).__name__} names no train function; a "
                                  "learner's config is a subclass, e.g. evo.learners.ppo.PPO")

    @property
    def frames_per_batch(self) -> int:
        """Env steps per collector batch (all arenas)."""
        return self.num_envs * self.rollout_steps


class RunningNorm(nn.Module):
    """Observation normalisation with running mean and variance (kept as buffers).

    ``update`` merges a batch's statistics (Chan et al.'s parallel formula); the forward
    pass standardises and clips to ``[-clip, clip]``.
    """

    count: torch.Tensor
    mean: torch.Tensor
    var: torch.Tensor

    def __init__(self, size: int, clip: float = 10.0, enabled: bool = True) -> None:
        super().__init__()
        self.clip, self.enabled = clip, enabled
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(size))
        self.register_buffer("var", torch.ones(size))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Fold the rows of ``x`` (any leading shape, last dim = size) into the statistics."""
        if not self.enabled:
            return
        x = x.reshape(-1, x.shape[-1]).double()
        n = x.shape[0]
        total = self.count + n
        delta = x.mean(0) - self.mean.double()
        mean = self.mean.double() + delta * n / total
        m2 = self.var.double() * self.count + x.var(0, unbiased=False) * n
        m2 = m2 + delta**2 * self.count * n / total
        self.mean.copy_(mean)
        self.var.copy_(m2 / total)
        self.count.copy_(total)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.enabled or self.count == 0:
            return x
        return ((x - self.mean) / torch.sqrt(self.var + 1e-8)).clamp(-self.clip, self.clip)


def _mlp(inputs: int, outputs: int, hidden: tuple[int, ...], out_gain: float) -> MLP:
    """A tanh MLP with orthogonal initialisation (gain sqrt 2 inside, ``out_gain`` last)."""
    net = MLP(
        in_features=inputs, out_features=outputs, num_cells=list(hidden), activation_class=nn.Tanh
    )
    linears = [m for m in net.modules() if isinstance(m, nn.Linear)]
    for layer in linears:
        nn.init.orthogonal_(layer.weight, gain=out_gain if layer is linears[-1] else math.sqrt(2))
        nn.init.zeros_(layer.bias)
    return net


class GaussianHead(nn.Module):
    """Mean from an MLP of the normalised observation (squashed into [-1, 1] by tanh with
    ``bound_mean``), scale from a learned log std (at most ``log_std_cap``, when set)."""

    def __init__(
        self, norm: RunningNorm, obs: int, act: int, hidden: tuple[int, ...], init_log_std: float,
        out_gain: float = 0.01, bound_mean: bool = False,
    ) -> None:
        super().__init__()
        self.norm, self.mlp = norm, _mlp(obs, act, hidden, out_gain=out_gain)
        self.log_std = nn.Parameter(torch.full((act,), init_log_std))
        self.bound_mean = bound_mean
        self.log_std_cap: float | None = None  # set between batches by an annealing learner

    def forward(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        loc = self.mlp(self.norm(observation))
        if self.bound_mean:
            loc = torch.tanh(loc)
        log_std: torch.Tensor = self.log_std
        if self.log_std_cap is not None:
            log_std = log_std.clamp(max=self.log_std_cap)
        return loc, log_std.exp().expand_as(loc)


class GaussianSampler(nn.Module):
    """The actor's random action and its log-probability in one call: what a collector
    needs, without building a distribution object every step (the loss still reads the
    policy through the ``ProbabilisticActor``).

    It reads ``observation`` from a TensorDict and writes ``loc``, ``scale``,
    ``action`` and ``action_log_prob`` into it, as the ``ProbabilisticActor`` would,
    with four plain ``set`` calls instead of a ``TensorDictModule``'s key bookkeeping
    (a collector calls it once per control step).
    """

    def __init__(self, head: GaussianHead) -> None:
        super().__init__()
        self.head = head

    def sample(
        self, observation: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Mean, scale, a random action and its log-probability."""
        loc, scale = self.head(observation)
        noise = torch.randn_like(loc)
        action = loc + scale * noise
        # log N(action; loc, scale), summed over the independent action dimensions.
        log_prob = (-0.5 * noise**2 - scale.log() - 0.5 * math.log(2 * math.pi)).sum(-1)
        return loc, scale, action, log_prob

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        loc, scale, action, log_prob = self.sample(tensordict.get("observation"))
        tensordict.set("loc", loc)
        tensordict.set("scale", scale)
        tensordict.set("action", action)
        tensordict.set("action_log_prob", log_prob)
        return tensordict


class ValueHead(nn.Module):
    """State value from an MLP of the normalised observation."""

    def __init__(self, norm: RunningNorm, obs: int, hidden: tuple[int, ...]) -> None:
        super().__init__()
        self.norm, self.mlp = norm, _mlp(obs, 1, hidden, out_gain=1.0)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        value: torch.Tensor = self.mlp(self.norm(observation))
        return value


class Checkpoint(TypedDict):
    """A policy's ``.pt`` file (``torch.save`` of this dict): :meth:`Policy.state_dict`,
    and what :func:`save_checkpoint` adds."""

    obs_size: int
    action_size: int
    actor: dict[str, torch.Tensor]  # the modules' state_dict()
    critic: dict[str, torch.Tensor]
    hidden: NotRequired[list[int]]
    normalize_obs: NotRequired[bool]
    bound_mean: NotRequired[bool]
    robot: NotRequired[str]  # the hash of the structure it was trained on


@dataclass
class Policy:
    """The networks of one learner: actor, critic and their shared normaliser."""

    norm: RunningNorm
    actor: ProbabilisticActor
    critic: ValueOperator

    @property
    def head(self) -> GaussianHead:
        """The actor's network: observation to Gaussian mean and scale."""
        head: GaussianHead = self.actor.module[0].module
        return head

    @torch.no_grad()
    def mean_action(self, observation: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean for ``observation``: the deterministic action, computed
        without TensorDict bookkeeping (for step-by-step play)."""
        loc: torch.Tensor = self.head(observation)[0]
        return loc

    @property
    def value_head(self) -> ValueHead:
        """The critic's network: observation to state value."""
        head: ValueHead = self.critic.module
        return head

    def sampler(self) -> GaussianSampler:
        """The exploring actor for collectors (shares the weights)."""
        return GaussianSampler(self.head)

    def state_dict(self) -> Checkpoint:
        """Everything a checkpoint needs (tensors and plain numbers only)."""
        return {
            "obs_size": int(self.head.mlp[0].in_features),
            "action_size": int(self.head.log_std.numel()),
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
        }


@dataclass(frozen=True)
class Inheritance:
    """A parent's trained policy for a child to start from (``ga.inheritance``).

    Attributes:
        parent: The parent's policy (``load_checkpoint`` of its ``evals/<name>.pt``).
        actuators: For each actuator of the child, in action order, the parent's
            actuator it follows, or -1 for one without a counterpart there
            (``evo.components.inheritance.PolicyStart.actuators``).
    """

    parent: Policy
    actuators: tuple[int, ...]


def _linears(module: nn.Module) -> list[nn.Linear]:
    return [m for m in module.modules() if isinstance(m, nn.Linear)]


@torch.no_grad()
def inherit(policy: Policy, start: Inheritance) -> None:
    """Overwrite a fresh ``policy`` with the parent's, slot by slot.

    The networks are MLPs whose first layer reads the observation and whose last layer
    writes one action per actuator, so a module's slots are columns of the first layers
    (actor and critic), rows of the actor's last layer and entries of its log standard
    deviation and of the observation statistics (``evo.envs.params.observation_origins``
    gives the columns). Every slot with a counterpart takes the parent's values; the
    hidden layers, the critic's output and the normaliser's sample count are the
    parent's; a slot without a counterpart keeps the fresh policy's values, as a module
    of a new robot would (its statistics mean 0 and variance 1, weighed with the
    parent's count). On an identical body every value is the parent's.

    Raises:
        ValueError: The two policies differ in hidden layers or in what the task adds
            to the observation, or an actuator index is out of the parent's range.
    """
    parent, actuators = start.parent, start.actuators
    obs, act = int(policy.head.mlp[0].in_features), int(policy.head.log_std.numel())
    p_obs, p_act = int(parent.head.mlp[0].in_features), int(parent.head.log_std.numel())
    shapes = [tuple(x.weight.shape) for x in _linears(policy.head.mlp)[1:-1]]
    if shapes != [tuple(x.weight.shape) for x in _linears(parent.head.mlp)[1:-1]] or (
            _linears(policy.head.mlp)[0].out_features
            != _linears(parent.head.mlp)[0].out_features):
        raise ValueError("inherit: the parent's policy has other hidden layers "
                         "(learner.hidden must be the same for parent and child)")
    if obs - ACTUATOR_SLOTS * act != p_obs - ACTUATOR_SLOTS * p_act:
        raise ValueError(f"inherit: the parent observes {p_obs} values for {p_act} actuators, "
                         f"the child {obs} for {act}: other env settings (observe_up, "
                         "observe_stall, observe_range, observe_clock)")
    if len(actuators) != act or not all(-1 <= k < p_act for k in actuators):
        raise ValueError(f"inherit: {list(actuators)} does not map the child's {act} actuators "
                         f"to the parent's {p_act}")
    obs_map = observation_origins(actuators, p_act, p_obs)
    cols = [i for i, k in enumerate(obs_map) if k >= 0]
    p_cols = [obs_map[i] for i in cols]
    rows = [j for j, k in enumerate(actuators) if k >= 0]
    p_rows = [actuators[j] for j in rows]
    policy.norm.count.copy_(parent.norm.count)
    policy.norm.mean[cols] = parent.norm.mean[p_cols]
    policy.norm.var[cols] = parent.norm.var[p_cols]
    policy.head.log_std[rows] = parent.head.log_std[p_rows]
    for mine, theirs, out_rows in ((policy.head.mlp, parent.head.mlp, (rows, p_rows)),
                                   (policy.value_head.mlp, parent.value_head.mlp, None)):
        layers, parents = _linears(mine), _linears(theirs)
        layers[0].weight[:, cols] = parents[0].weight[:, p_cols]
        layers[0].bias.copy_(parents[0].bias)
        for layer, source in zip(layers[1:-1], parents[1:-1], strict=True):
            layer.load_state_dict(source.state_dict())
        if out_rows is None:
            layers[-1].load_state_dict(parents[-1].state_dict())
        else:
            layers[-1].weight[out_rows[0]] = parents[-1].weight[out_rows[1]]
            layers[-1].bias[out_rows[0]] = parents[-1].bias[out_rows[1]]


def make_policy(obs_size: int, action_size: int, config: LearnerConfig) -> Policy:
    """Fresh actor and critic for ``obs_size`` observations and ``action_size`` actions."""
    norm = RunningNorm(obs_size, enabled=config.normalize_obs)
    head = GaussianHead(norm, obs_size, action_size, config.hidden, config.init_log_std,
                        config.policy_out_gain, config.bound_mean)
    actor = ProbabilisticActor(
        TensorDictModule(head, in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        distribution_class=IndependentNormal,
        return_log_prob=True,
    )
    critic = ValueOperator(ValueHead(norm, obs_size, config.hidden), in_keys=["observation"])
    return Policy(norm, actor, critic)


@dataclass
class TrainResult:
    """What one training run returns.

    Attributes:
        fitness: Mean return of all episodes completed during the run (paper Eq. 8);
            when none completed, the mean return so far of the unfinished ones.
        curve: One row per collector batch (see ``evo.learners.ppo``).
        policy: The trained networks.
        env_steps: Env steps taken.
        episodes: Episodes completed.
        wall_seconds: Wall time of the run.
        unstable: Episodes ended by a numerical blow-up.
        timing: Seconds spent in physics, the rest of the env, policy and update.
        stopped_early: The curve hook stopped training before the budget was spent.
        kept_at: With ``keep_best``, the env steps at which the handed-back policy was
            evaluated best; None when it is the last one.
        evaluation: The periodic evaluation (success rate, mean return) of the
            handed-back policy: the last one, or the best with ``keep_best``; None
            without ``eval_interval``.
    """

    fitness: float
    curve: pd.DataFrame
    policy: Policy
    env_steps: int
    episodes: int
    wall_seconds: float
    unstable: int = 0
    timing: dict[str, float] = field(default_factory=dict)
    stopped_early: bool = False
    kept_at: int | None = None
    evaluation: tuple[float, float] | None = None

    @property
    def steps_per_second(self) -> float:
        """Env steps per wall second, end to end."""
        return self.env_steps / max(self.wall_seconds, 1e-9)


def save_checkpoint(policy: Policy, path: Path, config: LearnerConfig, *,
                    robot: str = "") -> Path:
    """Write the policy to ``path``; ``torch.load(path, weights_only=True)`` reads it.

    Besides the weights it stores the observation and action sizes and ``robot``, the
    hash of the structure it was trained on, which :func:`load_checkpoint` checks.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    state = policy.state_dict()
    state["hidden"] = list(config.hidden)
    state["normalize_obs"] = config.normalize_obs
    if config.bound_mean:  # the mean action is tanh of the network's output
        state["bound_mean"] = True
    state["robot"] = robot
    data = io.BytesIO()  # torch reports a failed write without its cause: written here
    torch.save(state, data)
    return write_bytes(path, data.getvalue())


class SavePolicy(Protocol):
    """Writes a trained policy (:func:`save_checkpoint` is evo's own).

    ``evo.evaluation.evaluate`` takes one beside its learner: a writer that also
    exports the policy in another form is one of this signature. What it writes at
    ``path`` is what :func:`load_checkpoint` reads (a child's inherited policy, a replay).
    """

    def __call__(self, policy: Policy, path: Path, config: LearnerConfig, *,
                 robot: str = "") -> Path: ...


def load_checkpoint(path: Path, *, robot: Robot | None = None,
                    obs_size: int | None = None) -> Policy:
    """The policy saved by ``save_checkpoint``.

    Args:
        path: The checkpoint.
        robot: The robot it is to drive, or None: then it must have been trained on
            this structure (when the checkpoint names one) and act on as many actuators.
        obs_size: The observation size of the env it is to run in, or None.

    Raises:
        ValueError: A missing, unreadable or foreign file, or one that does not fit
            ``robot`` or ``obs_size``; the message names the file and what is expected.
    """
    if path.is_dir():
        raise ValueError(f"{path}: a folder, not a policy checkpoint (a .pt file)")
    try:
        state = torch.load(path, weights_only=True)
        config = LearnerConfig(
            hidden=tuple(state["hidden"]), normalize_obs=bool(state["normalize_obs"]),
            bound_mean=bool(state.get("bound_mean", False)),
        )
        sizes = int(state["obs_size"]), int(state["action_size"])
        policy = make_policy(*sizes, config)
        policy.actor.load_state_dict(state["actor"])
        policy.critic.load_state_dict(state["critic"])
    except FileNotFoundError:
        raise ValueError(f"{path}: no such checkpoint") from None
    except Exception as err:  # noqa: BLE001 - torch raises many kinds for a bad file
        reason = str(err).split(". ")[0].strip() or type(err).__name__
        raise ValueError(f"{path}: not an evo policy checkpoint ({reason})") from None
    trained_on = str(state.get("robot", ""))
    if robot is not None:
        if trained_on and trained_on != robot.hash:
            raise ValueError(f"{path}: trained on robot-{trained_on[:8]}, not on {robot.name}; "
                             "give the checkpoint of this robot")
        if sizes[1] != action_size(robot):
            raise ValueError(f"{path}: the policy acts on {sizes[1]} actuators but "
                             f"{robot.name} has {action_size(robot)}")
    if obs_size is not None and sizes[0] != obs_size:
        raise ValueError(f"{path}: the policy observes {sizes[0]} values but this env gives "
                         f"{obs_size}; run it with the env settings it was trained with "
                         "(env.task.observe_up adds 3, env.task.observe_stall 1, "
                         "env.task.observe_range env.task.range_sectors, env.task.observe_clock 2)")
    return policy

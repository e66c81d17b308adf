"""The continuous agents' two losses (farsighter.agents.naf): NAF's TD loss on theta, theta_V,
theta_P (Algorithm 3 line 9) and the ELBO of Eq. 10 for the Bayesian mu-layer.

**TD** (:class:`NAFLoss`): y = r^k + gamma^n (1 - terminal) V'(s') (Eq. 8 with argmax_a' Q = mu,
so max Q' = V'), from the target network, which the loss owns and which moves by soft updates;
Q of Eq. 4 with the Bayesian mu-layer at its posterior mean and out of the gradient; for a plain
mu-layer a penalty on its pre-tanh output (``NAFConfig.mu_penalty``).

**ELBO** (:class:`ElboLoss`), as we read Eq. 10 (SPEC 2.2): loss = KL(q || prior) -
E_q[log p(y | theta^a)], where the data are the TD targets y_i of a replay minibatch (the same
targets as the TD update) and the likelihood is Gaussian, y_i ~ N(Q(s_i, a_i | theta^a),
sigma_eps^2), with Q of Eq. 4 evaluated at the STORED action a_i, with the frozen
representation, V and P, and with mu = scale(tanh(output)) of the mu-layer under weights drawn
from q (local reparameterisation, one draw per row). phi, V, L and y are computed without
gradient and only the mu-layer is in the optimiser, so theta, theta_V, theta_P cannot move. The
KL is divided by the number of replay rows (``elbo_loss``'s per-datum form). The mu-layer's means
thereby follow the NAF TD gradient, and its variances shrink only where the targets pin mu down.
The same pre-tanh penalty as the TD loss applies to the posterior mean's output.
"""

from __future__ import annotations

import copy
from functools import partial

import torch
import torch.nn.functional as F

from farsighter.agents.common import TensorBatch, td_loss
from farsighter.agents.cuda_graph import Tensors
from farsighter.config import Config
from farsighter.networks import NAFNetwork
from farsighter.ops.bayes_layer import BayesianLinear, elbo_terms
from farsighter.ops.naf import naf_q, naf_td_target


class NAFLoss:
    """Algorithm 3 line 9 on a k-step minibatch (module docstring)."""

    def __init__(self, net: NAFNetwork, cfg: Config, bayesian: bool) -> None:
        self.net = net
        self.net_target = copy.deepcopy(net).requires_grad_(False)
        self.kind, self.mu_penalty, self.bayesian = cfg.loss, cfg.naf.mu_penalty, bayesian

    @torch.no_grad()
    def targets(self, t: TensorBatch) -> torch.Tensor:
        """y = r^k + gamma^n (1 - terminal) V'(s_{t+n}) from the target network."""
        return naf_td_target(t.returns_B, t.bootstrap_B, self.net_target.value(t.next_obs_B))

    def __call__(self, inputs: Tensors) -> Tensors:
        t = TensorBatch.of(inputs)
        y_B = self.targets(t)
        q_B, out_BA = self.net.q(t.obs_B, t.actions_B, freeze_mu=self.bayesian)
        loss = td_loss(q_B, y_B, self.kind)
        if not self.bayesian:  # keep tanh(mu) out of saturation (NAFConfig.mu_penalty)
            loss = loss + self.mu_penalty * out_BA.pow(2).mean()
        return {"loss": loss}

    @torch.no_grad()
    def soft_update(self, tau: float) -> None:
        """theta' <- tau theta + (1 - tau) theta' (Algorithm 3 line 11)."""
        for p_target, p in zip(self.net_target.parameters(), self.net.parameters(), strict=True):
            p_target.lerp_(p, tau)


class ElboLoss:
    """Eq. 10 for the Bayesian mu-layer of ``td.net`` (module docstring); draws its weights from
    ``gen``. ``num_data`` (the replay's rows) is set before each round of ELBO steps."""

    def __init__(self, td: NAFLoss, cfg: Config, gen: torch.Generator) -> None:
        assert isinstance(td.net.mu_layer, BayesianLinear)
        self.td, self.layer, self.naf, self.gen = td, td.net.mu_layer, cfg.naf, gen
        self.num_data = 1

    def __call__(self, inputs: Tensors) -> Tensors:
        t, net = TensorBatch.of(inputs), self.td.net
        with torch.no_grad():
            y_B = self.td.targets(t)
            phi_BD = net.torso(t.obs_B)
            v_B, l_BAA = net.head(phi_BD)
        # predict_fn(out) = Q(s_i, a_i | mu = scale(tanh(out))) with V and P frozen.
        terms = elbo_terms(
            self.layer,
            phi_BD,
            partial(_q_at, net, v_B, l_BAA, t.actions_B),
            y_B,
            self.naf.noise_std_eps,
            self.num_data,
            kl_weight=self.naf.kl_weight,
            generator=self.gen,
        )
        mean_out_BA = F.linear(phi_BD, self.layer.weight_mu, self.layer.bias_mu)
        total = terms.loss + self.naf.mu_penalty * mean_out_BA.pow(2).mean()
        return {"loss": total, "elbo": terms.loss, "nll": terms.nll, "kl": terms.kl, "phi": phi_BD}


def _q_at(
    net: NAFNetwork,
    v_B: torch.Tensor,
    l_BAA: torch.Tensor,
    action_BA: torch.Tensor,
    out_BA: torch.Tensor,
) -> torch.Tensor:
    """Q(s, a) of Eq. 4 for a given mu-layer output (V and L given)."""
    return naf_q(v_B, net.mu_from_out(out_BA), l_BAA, action_BA)

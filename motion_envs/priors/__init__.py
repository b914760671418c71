"""Motion priors: GAMMA marker primitives, WANDR, CLOPS (nn.Modules, load/save, training)."""

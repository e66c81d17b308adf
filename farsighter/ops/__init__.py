"""Pure math, each piece tested against closed forms: k-step targets (:mod:`targets`), the BLR
posterior and Thompson draws (:mod:`blr`), the Bayesian linear layer (:mod:`bayes_layer`), NAF's
head (:mod:`naf`) and the adaptive-k rule (:mod:`adaptive_k`)."""

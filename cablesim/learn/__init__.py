"""Learning from the simulator's exact ground truth: training pairs with camera effects
(:mod:`cablesim.learn.pairs`) and ``cablesim train`` for the learned flow back end
(:mod:`cablesim.learn.train`; the estimator itself is :mod:`cablesim.perception.learned`)."""

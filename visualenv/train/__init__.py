"""Training and trained agents: the SB3 (:mod:`~visualenv.train.sb3`) and Ray RLlib (:mod:`~visualenv.train.rllib`)
backends, the evaluation that reports a run (:mod:`~visualenv.train.evaluation`), loading and exporting models
(:mod:`~visualenv.train.model_files`), ``play`` and the training plots."""

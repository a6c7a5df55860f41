"""Running filters over a task: the one pipeline, ``replay eval``, its options, reruns, results as tables."""

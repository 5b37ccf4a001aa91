"""The networks (STRNN and the baselines), the dataset and their training."""

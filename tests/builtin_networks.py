"""The five networks nnfmu ships (nnfmu/networks/), which many tests run through every path; in nnfmu itself the
architecture records are the only source of names (tests/test_name_lists.py)."""

ARCHS = ("mlp", "rnn", "lstm", "gru", "tcn")

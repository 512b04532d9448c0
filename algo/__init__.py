"""The algorithm core: policy network, n-step returns and the D-A3C updates. No transport code."""

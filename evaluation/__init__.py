"""The paper's experiments: Table I protocol, TTC baseline, right-of-way test."""

"""Training loops (needs the ``train`` extra: torch, torchrl, tensordict)."""

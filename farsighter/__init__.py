"""Farsighter: uncertainty-driven multi-step exploration for deep RL."""

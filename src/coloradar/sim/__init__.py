"""Physically based simulation of ColoRadar runs (built-in sample data and known-truth tests)."""

from .radar_if import apply_channel_errors, slow_times, synthesize_adc

__all__ = ["apply_channel_errors", "slow_times", "synthesize_adc"]

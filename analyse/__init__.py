"""Analyse stage: designs of experiments, ANOVA and regression, optimisation, the calibration campaign."""

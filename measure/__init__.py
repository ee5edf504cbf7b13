"""Measure stage: a lab workbook in, every DEM material parameter out (with uncertainty and provenance)."""

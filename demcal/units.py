"""Constants and units, in one place.

Inside demcal every computation is in SI (m, kg, s, rad). The lab workbook states lengths in mm
and angles in degrees (its column names say so: ``length_mm``, ``tilt_deg``); the measure stage
publishes each quantity with its unit (``Estimate.unit``) and the campaign converts with the
factors below.
"""

from __future__ import annotations

#: Gravitational acceleration used by every twin and every measurement [m/s^2]. The value the
#: source paper's EDEM set-up and LIGGGHTS decks use; the local value of a lab differs from it
#: by less than 0.2 %.
GRAVITY = 9.81

#: Metres per millimetre.
MM = 1e-3

"""Published reference used by several analyse tests: the source paper's regression equation.

Source paper (seed), eq. 5, coded A = e particle-particle, B = e particle-steel,
C = mu_s particle-steel: 35.65 - 0.5775A - 0.66B + 0.22C + 2.45AB - 0.4925AC + 1.41BC
+ 0.7408A^2 + 0.6557B^2 - 1.11C^2 [deg]; published fit statistics R2 0.9717, adj R2 0.9354,
Adeq Precision 22.7736, C.V. 1.25 %.
"""

PAPER_EQ5 = {"Intercept": 35.65, "A": -0.5775, "B": -0.66, "C": 0.22, "AB": 2.45, "AC": -0.4925,
             "BC": 1.41, "A^2": 0.7408, "B^2": 0.6557, "C^2": -1.11}


def paper_eq5(x):
    """Eq. 5 evaluated at coded points x, shape (n, 3) [deg]."""
    a, b, c = x.T
    k = PAPER_EQ5
    return (k["Intercept"] + k["A"] * a + k["B"] * b + k["C"] * c + k["AB"] * a * b
            + k["AC"] * a * c + k["BC"] * b * c + k["A^2"] * a ** 2 + k["B^2"] * b ** 2
            + k["C^2"] * c ** 2)

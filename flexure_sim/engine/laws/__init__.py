"""
Hinge laws: potentials in twistor or twist coordinates and what follows from them.

- ``coordinates``: Law coordinates c(r) of a hinge's relative displacement r = (alpha, p1, p2),
  with derivatives.
- ``hinge_force``: One hinge's generalised forces under a quadratic law: the hinge force chain,
  written once.
- ``monomials``: Monomial algebra of the polynomial hinge laws (Appendix B of the dissertation).
- ``polynomial``: Polynomial hinge laws: potentials of order N in twistor or twist coordinates
  (4.69, 3.67).
- ``quadratic``: Hinge laws: potential energy, wrench and dissipation of an elastic element (Ch. 3,
  4).
- ``spatial``: Spatial hinge laws: law coordinates (twistor, twist), potential, wrench, energy and
  power.
"""

"""
Data-driven hinges: wrench data and polynomial laws fitted to them (Chapter 7).

- ``datasets``: Synthetic (displacement, wrench) data for fitting polynomial hinges.
- ``least_squares``: Fitting polynomial hinge laws to measured (displacement, wrench) pairs (Ch. 7,
  Appendix B).
- ``randomtest``: Chapter 7.1 reproduced: the dissertation's fit of generalized forces on random
  data.
- ``wrench_data``: Measured (displacement, wrench) pairs of a hinge and their CSV files.
"""

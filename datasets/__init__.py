"""Readers of real logs (marina layout, keyframes, raw ``_IS.log``), geodesy, the MSIS simulator."""

"""The AxiDraw (EiBotBoard) as a tagbot machine: profiles, timed low-level moves, streaming."""

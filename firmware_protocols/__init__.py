"""Wire protocols shared by the tagbot host and the simulated devices.

This package holds the byte-level formats both ends speak: G-code lines and status reports as
understood by Grbl pen plotters, and DYNAMIXEL Protocol 2.0 instruction and status packets for
servo arms. It must not import ``tagbot`` or ``sim``, so host and simulators share one definition.
"""

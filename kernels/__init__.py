"""Warp kernels of lodprt, installed as ``lodprt.kernels``; one module per concept.

Kernels are pure functions of their arrays: the host side (``lodprt``) owns allocation, devices and scheduling.
"""

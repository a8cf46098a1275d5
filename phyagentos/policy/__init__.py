"""Policies for the policy-driven flow, served over openpi's websocket protocol.

==================  ===========================================================
module              what
==================  ===========================================================
``wire``            msgpack + numpy framing, byte-compatible with openpi-client
``client``          PolicyClient: handshake, metadata, infer, heartbeat, timeouts
``server``          PolicyServer: serves any ``infer(obs) -> dict`` object
``grasp_policy``    GraspPolicy: a mink reach-and-grasp controller as a policy
``observation``     the observation contract handed to adapters
``adapter``         PolicyAdapter: observation -> model inputs, outputs -> actions
==================  ===========================================================

Part of the Runtime plane (``.importlinter``): it never imports the Agent plane.
"""

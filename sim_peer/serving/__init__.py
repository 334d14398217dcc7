"""A world served on the fabric: the peer, its robot streams, the commands it takes in and the answers and events it
gives.
"""

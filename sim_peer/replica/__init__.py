"""Replicated authority: the election, a sim's role and its token, what a standby follows and keeps, and the guards of
a primary that was frozen, cut off, or left scene objects behind.
"""

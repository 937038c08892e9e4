# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact first-order reference: every first-order reflection of a point and its
visibility (:mod:`.exact`), and images polished on the true reflected rays of the mirror
mesh (:mod:`.true_rays`), what the sample-based camera and the live accuracy check polish
and verify with. The references only tests and benchmarks measure against (second-order
paths, closed forms on declared exact surfaces) live in ``tools/``, outside the zip."""

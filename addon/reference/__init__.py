# SPDX-License-Identifier: GPL-3.0-or-later
"""The exact reference every method is measured against: every first-order reflection of
a point and its visibility (:mod:`.exact`), second-order paths (:mod:`.exact_paths`),
closed forms on declared exact surfaces (:mod:`.exact_analytic`), and images polished on
the true reflected rays of the mirror mesh (:mod:`.true_rays`, also what the sample-based
camera and the live accuracy check polish and verify with)."""

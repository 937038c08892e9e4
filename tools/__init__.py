# SPDX-License-Identifier: GPL-3.0-or-later
"""Development and benchmark helpers: everything the tests, the benchmarks and the scripts
share that the extension itself never runs. Not shipped (``blender_manifest.toml``
excludes ``/tools/``), and no shipped module imports it (``tests/test_layout.py``).

- reference renders (Cycles, EEVEE, the reflector mask) and PNG read-back
  (:mod:`.reference_render`), and label metrics against them (:mod:`.metrics`);
- exact references beyond the product's first-order solver: second-order paths
  (:mod:`.exact_paths`), closed forms on declared exact surfaces (:mod:`.exact_analytic`),
  the mirror sphere's closed-form reflection and held-out test surfaces (:mod:`.surfaces`);
- earlier paths kept as references to measure against: ray maps by rasterisation
  (:mod:`.raymap_gpu`) and the morphing blend in numpy (:mod:`.numpy_morph_source`);
- the extension's import graph read from source (:mod:`.import_graph`), for the layout and
  packaging tests.

It lives at the repository root, not under ``tests/``, because the benchmarks and
``scripts/`` use it as much as the tests do; tests and scripts import it as
``curved_reflections.tools`` (``scripts/package_link.py``), and inside it imports of the
extension are relative, as in the extension.
"""

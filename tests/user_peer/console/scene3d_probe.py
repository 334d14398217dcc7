"""What the console's 3D view drew, read from the page (three.js through NiceGUI's ``getElement``), for the
browser tests: each link's cylinder ends in the world, the IK target's sphere and its place on the screen; and a
real mouse drag of that sphere.

The sphere is read where it was last drawn (its ``matrixWorld``, seen through the camera as last drawn), not where
it was last moved to (its ``position``): three.js updates those matrices only when it renders, 2 times a second in
these tests (``--view-fps 2``), and the drag's ray is cast against them. A drag aimed at a sphere moved but not yet
drawn missed it, and nothing moved (1 run in 4 of the 3D test alone, 2026-12-04); a user aims at what she sees."""

from __future__ import annotations

SCENE3D_JS = """() => {
  const s = getElement(document.querySelector('.rf-scene3d'));
  if (!s || !s.scene) return null;
  const m = s.scene.getObjectByName('ik-target');
  const r = s.renderer.domElement.getBoundingClientRect();
  const ends = [];
  s.scene.traverse((c) => {
    if (c.geometry && c.geometry.type === 'CylinderGeometry') {
      for (const sign of [-1, 1]) {
        const e = c.up.clone().set(0, sign * c.scale.y / 2, 0).applyQuaternion(c.quaternion).add(c.position);
        ends.push([e.x, e.y, e.z]);
      }
    }
  });
  if (!m || !m.visible) return {ends};
  const w = m.position.clone().setFromMatrixPosition(m.matrixWorld);  // as last drawn
  const v = w.clone().applyMatrix4(s.camera.matrixWorldInverse).applyMatrix4(s.camera.projectionMatrix);
  return {ends, target: [w.x, w.y, w.z],
          screen: [r.left + (v.x + 1) / 2 * r.width, r.top + (1 - v.y) / 2 * r.height]};
}"""


def drag_sphere(page, screen: tuple[float, float]) -> None:
    """A real mouse drag from the sphere's place on the screen, 20 px right and 10 px up in five moves."""
    x0, y0 = screen
    page.mouse.move(x0, y0)
    page.mouse.down()
    for k in range(1, 6):
        page.mouse.move(x0 + 4 * k, y0 - 2 * k)
    page.mouse.up()

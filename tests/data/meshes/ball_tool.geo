// A round instrument tip for scripts/edge-slide (docs/free-interaction.md, "A round tool sliding
// off a convex edge"): a ball of radius `radius` with a handle of radius 0.75 radius and length
// 3 radius above it, centred at the origin. Lengths in mm (length_unit_m: 0.001). Physical
// groups: "ball" (volume), "handle" (the handle's flat top: the driven group).
SetFactory("OpenCASCADE");
radius = 2;  // scripts/edge-slide rewrites this line
Sphere(1) = {0, 0, 0, radius};
Cylinder(2) = {0, 0, 0, 0, 0, 3 * radius, 0.75 * radius};
BooleanUnion(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Physical Volume("ball") = {3};
Physical Surface("handle") = Surface In BoundingBox{-radius, -radius, 3 * radius - 0.01, radius, radius, 3 * radius + 0.01};

"""The numba kernels of the mesh intake and checks, by module of ``preform._kernels``."""

INTAKE_KERNELS = {
    "mesh": ("vertex_bounds", "weld_exact", "grid_neighbours_exist", "degenerate_faces", "edge_ray_geometry",
             "winding_numbers",
             "edge_ray_batch", "edge_ray_hits", "centroids_and_reach", "face_cross_normals", "corner_cosines",
             "corners_by_vertex", "corner_normals"),
    "edges": ("merge_clusters", "first_of_each_face", "orient_bodies", "edge_table", "directed_neighbors"),
    "sections": ("chain_loops",),
}

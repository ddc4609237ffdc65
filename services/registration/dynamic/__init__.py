"""Dynamic registration (paper II-C): 12 isolated views into one colored model.

Entry point: ``model.build_model(views, DynamicConfig(), map_pairs=None)``; see docs/dynamic-registration.md.
Modules are imported on use so that importing this package stays cheap for the service faces.
"""

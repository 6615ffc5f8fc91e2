"""Counting what a bake renders: resume tests assert that a resumed bake renders no view again."""

from __future__ import annotations


def count_rendered_views(monkeypatch) -> list[tuple[str, int]]:
    """Wrap the shared view-rendering stage (nasset_bakers.stages.render_views, imported by every baker when it
    runs) so each view it renders is appended to the returned list as (split, index)."""
    import nasset_bakers.stages as stages

    rendered: list[tuple[str, int]] = []
    original = stages.render_views

    def counting(store, views, val_views, render_one, **kw):
        def one(split, i):
            rendered.append((split, i))
            return render_one(split, i)

        return original(store, views, val_views, one, **kw)

    monkeypatch.setattr(stages, "render_views", counting)
    return rendered

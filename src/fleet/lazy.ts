import { lazy, type ComponentType, type LazyExoticComponent } from 'react';

/** The props of a component type. */
type PropsOf<C> = C extends ComponentType<infer P> ? P : never;

/** A view loaded when first shown (its own chunk), and loadable ahead of time (`preload`). */
export type LazyView<P> = LazyExoticComponent<ComponentType<P>> & {
  /** Starts loading the view's code now (on hover, on idle); the same promise every time. */
  preload(): Promise<unknown>;
};

/**
 * A family's tab or page, split from the first screen (issue 16): `lazyView(() =>
 * import('./views/Files'), 'Files')`. Rendered inside a Suspense boundary (the machine page has
 * one per tab); a chunk that fails to load is an error of that tab (its error boundary).
 */
export function lazyView<M extends { [k in K]: ComponentType<never> }, K extends string>(
  load: () => Promise<M>,
  name: K,
): LazyView<PropsOf<M[K]>> {
  type P = PropsOf<M[K]>;
  let loading: Promise<M> | null = null;
  let loaded: M | null = null;
  const get = (): Promise<M> => {
    loading ??= load().then(
      (m) => (loaded = m),
      (e: unknown) => {
        // A failed load may succeed later (the console server restarted): try again next time.
        loading = null;
        throw e;
      },
    );
    return loading;
  };
  const view = lazy(() =>
    // Already loaded (preloaded on hover or idle): a thenable that answers at once, so React
    // renders the view in this pass instead of showing its fallback and then holding the view back
    // (React keeps a fallback at least 300 ms once shown).
    loaded
      ? (resolvedThenable({ default: loaded[name] as ComponentType<P> }) as Promise<{
          default: ComponentType<P>;
        }>)
      : get().then((m) => ({ default: m[name] as ComponentType<P> })),
  ) as LazyView<P>;
  view.preload = get;
  return view;
}

/** A thenable that calls back synchronously (React's lazy reads it as resolved at once). */
function resolvedThenable<T>(value: T): PromiseLike<T> {
  return {
    then<A = T, B = never>(ok?: ((v: T) => A | PromiseLike<A>) | null): PromiseLike<A | B> {
      return resolvedThenable(ok ? (ok(value) as A) : (value as unknown as A));
    },
  };
}

/** Whether a component is a lazy view (it can be loaded ahead of time). */
function preloadOf(c: unknown): (() => Promise<unknown>) | null {
  const p = (c as { preload?: unknown } | null)?.preload;
  return typeof p === 'function' ? (p as () => Promise<unknown>) : null;
}

/**
 * Loads views' code ahead of time, quietly (a failure shows when the view is opened). Used on
 * hover, focus or touch of a machine's link (its first tab) and, once a machine page shows, for
 * its other tabs when the browser is idle.
 */
export function preloadViews(components: readonly unknown[]): void {
  for (const c of components) void preloadOf(c)?.().catch(() => undefined);
}

/** Runs `fn` when the browser is idle (or after `fallbackMs` where there is no idle callback). Returns: cancel. */
export function whenIdle(fn: () => void, fallbackMs = 1500): () => void {
  const g = globalThis as {
    requestIdleCallback?: (cb: () => void) => number;
    cancelIdleCallback?: (h: number) => void;
  };
  if (g.requestIdleCallback && g.cancelIdleCallback) {
    const h = g.requestIdleCallback(fn);
    const cancel = g.cancelIdleCallback;
    return () => cancel(h);
  }
  const t = setTimeout(fn, fallbackMs);
  return () => clearTimeout(t);
}

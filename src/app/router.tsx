import {
  useEffect,
  useSyncExternalStore,
  type AnchorHTMLAttributes,
  type MouseEvent,
  type ReactNode,
} from 'react';

/** A tiny history router: the console has a handful of routes and bookmarkable machine pages. */
const listeners = new Set<() => void>();

function notify(): void {
  for (const l of listeners) l();
}

if (typeof window !== 'undefined') window.addEventListener('popstate', notify);

export function navigate(to: string, replace = false): void {
  if (to === location.pathname + location.search) return;
  if (replace) history.replaceState(null, '', to);
  else history.pushState(null, '', to);
  window.scrollTo(0, 0);
  notify();
}

function subscribe(fn: () => void): () => void {
  listeners.add(fn);
  return () => listeners.delete(fn);
}

/** Calls `fn` after every change of the page's location (in-app navigation, back, forward). */
export function onLocationChange(fn: () => void): () => void {
  return subscribe(fn);
}

export function useLocation(): { pathname: string; search: string } {
  const href = useSyncExternalStore(
    subscribe,
    () => location.pathname + location.search,
    () => '/',
  );
  const u = new URL(href, 'http://x');
  return { pathname: u.pathname, search: u.search };
}

/**
 * The page's title in the browser's tab, history and a screen reader's announcement:
 * "<what> · Shopdeck" ("Laser 1 — Running · Shopdeck", "Fleet · Shopdeck").
 */
export function usePageTitle(what: string): void {
  useEffect(() => {
    document.title = what ? `${what} · Shopdeck` : 'Shopdeck';
  }, [what]);
}

/** A page whose own code does not name it (a family's page, "no page here"): titled around it. */
export function Titled(props: { title: string; children: ReactNode }) {
  usePageTitle(props.title);
  return props.children;
}

/** An in-app link: a real `<a href>` (open in a new tab, copy, bookmark), navigated in place. */
export function Link(
  props: AnchorHTMLAttributes<HTMLAnchorElement> & {
    to: string;
    /** Replace the current history entry instead of adding one (sections of one page). */
    replace?: boolean;
  },
) {
  const { to, onClick, replace, children, ...rest } = props;
  return (
    <a
      {...rest}
      href={to}
      onClick={(e: MouseEvent<HTMLAnchorElement>) => {
        onClick?.(e);
        if (e.defaultPrevented || e.button !== 0 || e.metaKey || e.ctrlKey || e.shiftKey || e.altKey) return;
        e.preventDefault();
        navigate(to, replace);
      }}
    >
      {children}
    </a>
  );
}

export type Route =
  | { name: 'fleet' }
  /** `kiosk`: `/m/<id>?kiosk`, the machine alone, full screen (src/app/kiosk/); absent otherwise. */
  | { name: 'machine'; id: string; tab: string | null; kiosk?: true }
  | { name: 'audit' }
  | { name: 'alarms' }
  | { name: 'history' }
  | { name: 'login' }
  | { name: 'wall' }
  | { name: 'family-page'; kind: string; page: string }
  | { name: 'not-found' };

/** One path segment decoded, or null for a malformed escape (`%E0%A4%A`, a lone `%`). */
function decodeSegment(segment: string): string | null {
  try {
    return decodeURIComponent(segment);
  } catch {
    return null;
  }
}

/** Never throws: a path that cannot be decoded is the not-found route (rendered by the app). */
export function matchRoute(pathname: string, search = ''): Route {
  const parts: string[] = [];
  for (const segment of pathname.split('/').filter(Boolean)) {
    const part = decodeSegment(segment);
    if (part === null) return { name: 'not-found' };
    parts.push(part);
  }
  if (parts.length === 0) return { name: 'fleet' };
  if (parts[0] === 'm' && parts[1]) {
    const route: Route = { name: 'machine', id: parts[1], tab: parts[2] ?? null };
    return new URLSearchParams(search).has('kiosk') ? { ...route, kiosk: true } : route;
  }
  if (parts[0] === 'audit' && parts.length === 1) return { name: 'audit' };
  if (parts[0] === 'alarms' && parts.length === 1) return { name: 'alarms' };
  if (parts[0] === 'history' && parts.length === 1) return { name: 'history' };
  if (parts[0] === 'login' && parts.length === 1) return { name: 'login' };
  if (parts[0] === 'wall' && parts.length === 1) return { name: 'wall' };
  if (parts.length === 2 && parts[0] && parts[1])
    return { name: 'family-page', kind: parts[0], page: parts[1] };
  return { name: 'not-found' };
}

import { lazyView } from '../fleet/lazy';

/**
 * The console's pages, each a chunk of its own loaded when its route is first shown (issue 16):
 * a tablet opening one machine does not load the fleet page, nor the login form when it has a
 * session. The fleet page preloads the machine page when a tile's link is pointed at.
 */
export const FleetPage = lazyView(() => import('./FleetPage'), 'FleetPage');
export const MachinePage = lazyView(() => import('./MachinePage'), 'MachinePage');
/**
 * A kiosk tablet's view of one machine (`/m/<id>?kiosk`), shown by the machine page: a chunk of its
 * own (a machine page that is not a kiosk does not carry it), loaded beside the machine page's on
 * a kiosk (App), not after it.
 */
export const KioskPage = lazyView(() => import('./kiosk/KioskPage'), 'KioskPage');
export const LoginPage = lazyView(() => import('./auth/LoginPage'), 'LoginPage');
export const AuditPage = lazyView(() => import('./audit/AuditPage'), 'AuditPage');
export const AlarmsPage = lazyView(() => import('./alarms/AlarmsPage'), 'AlarmsPage');
export const WallPage = lazyView(() => import('./wall/WallPage'), 'WallPage');
export const HistoryPage = lazyView(() => import('./history/HistoryPage'), 'HistoryPage');

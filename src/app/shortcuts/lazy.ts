import { lazyView } from '../../fleet/lazy';

/** The shortcut handler and its help sheet: a chunk of their own (not in the first screen's). */
export const Shortcuts = lazyView(() => import('./Shortcuts'), 'Shortcuts');

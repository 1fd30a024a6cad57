import type { CSSProperties } from 'react';

/** Panels that share the width (the core's ui-grid keeps empty columns on wide screens). */
export const GRID: CSSProperties = { gridTemplateColumns: 'repeat(auto-fit, minmax(340px, 1fr))' };

/** Inputs that fill their panel without overflowing it (file pickers are wide otherwise). */
export const FULL_WIDTH: CSSProperties = { width: '100%', maxWidth: '100%', boxSizing: 'border-box' };

// The read worker's entry (reads.ts starts it): a worker thread does not inherit the TypeScript
// loader the server was started with (`npm start` registers tsx in its own thread only; vitest
// loads modules its own way), so it registers tsx itself, then loads the worker.
import { register } from 'tsx/esm/api';

register();
await import('./read-worker.ts');

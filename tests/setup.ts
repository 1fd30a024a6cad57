import { WebSocket as NodeWebSocket } from 'ws';
import { setApiOrigin } from '../src/fleet/origin';

// Node 20 has no global WebSocket: give msw's interceptor one to wrap.
if (typeof globalThis.WebSocket === 'undefined') {
  (globalThis as { WebSocket?: unknown }).WebSocket = NodeWebSocket;
}
// Requests from clients under test go to this origin; msw answers them.
setApiOrigin('http://shopdeck.test');
